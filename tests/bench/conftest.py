"""Fixtures of the bench tests."""

import pytest


@pytest.fixture
def bench_usage_error(tmp_path, capsys):
    """``check(argv, option)``: ``meshphase bench ... --out DIR argv`` is refused by argparse
    (exit 2, the option named on stderr) before the bench writes anything."""
    def check(argv, option):
        from meshphase.cli import main

        out = tmp_path / "b"
        with pytest.raises(SystemExit) as exc:
            main(["bench", *argv[:1], "--out", str(out), *argv[1:]])
        assert exc.value.code == 2 and option in capsys.readouterr().err
        assert not out.exists()

    return check
