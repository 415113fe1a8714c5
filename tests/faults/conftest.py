"""The fault corpus's table: after a session that ran corpus cases, their outcomes by
category (``fault_corpus.outcome_table``)."""


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    runs = config.__dict__.get("_corpus_outcomes")
    if runs:
        from fault_corpus import outcome_table

        terminalreporter.write_line("")
        for line in outcome_table(runs).splitlines():
            terminalreporter.write_line(line)
