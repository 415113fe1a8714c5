"""Run the ``meshphase bench`` commands at small sizes and write their tables into docs/bench/.

Each table file starts with the exact command that produced it; the benches' own Markdown
(``io_bench.md``, ``models_bench.md``, ``processing_bench.md``, ``conditions.md``) is copied
as written, less the run's timestamp; ``meshphase bench campaign`` prints its table, which is
kept as text. Run from the repository root (a few minutes on two cores)::

    python3 docs/bench/make_tables.py

The performance page (docs/performance.md) includes the files.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: table file -> (bench arguments, the Markdown file the bench writes into --out, or None:
#: its standard output is the table)
TABLES = {
    "io.md": (["io", "--quick"], "io_bench.md"),
    "models.md": (["models", "--quick"], "models_bench.md"),
    "processing.md": (["processing", "--quick"], "processing_bench.md"),
    "accuracy.md": (["processing", "--accuracy", "--quick"], "conditions.md"),
    "campaign.md": (["campaign", "--quick"], None),
}
#: an ISO 8601 date and time, with the separator before it (the run's timestamp)
STAMP = re.compile(r",? ?\d{4}-\d{2}-\d{2}T\d{2}:\d{2}:\d{2}(\.\d+)?([+-]\d{2}:\d{2}|Z)?")


def table(args: list[str], md_name: str | None, out: Path) -> str:
    """Run ``meshphase -q bench ARGS --out out`` and give its table as Markdown.

    Parameters
    ----------
    args : list of str
        The bench's arguments.
    md_name : str or None
        The Markdown file the bench writes into ``out``; None: its standard output.
    out : Path
        The bench's output folder (created).

    Returns
    -------
    str
        The table, headed by the command (``--out`` left out) and without timestamps.
    """
    exe = shutil.which("meshphase") or "meshphase"
    proc = subprocess.run([exe, "-q", "bench", *args, "--out", str(out)], check=True,
                          capture_output=True, text=True)
    command = "meshphase bench " + " ".join(args)
    if md_name is None:
        lines = [ln for ln in proc.stdout.splitlines() if not ln.startswith("campaign_bench.json")]
        body = "```text\n" + "\n".join(lines) + "\n```\n"
    else:
        text = (out / md_name).read_text(encoding="utf-8")
        body = re.sub(r"^# ", "### ", text, count=1, flags=re.M)
        body = body.replace("\n## ", "\n#### ")
    body = STAMP.sub("", body)
    return f"Produced by `{command}`:\n\n{body.rstrip()}\n"


def main() -> int:
    """Write every table of :data:`TABLES` into docs/bench/."""
    with tempfile.TemporaryDirectory() as tmp:
        for name, (args, md_name) in TABLES.items():
            (HERE / name).write_text(table(args, md_name, Path(tmp) / name[:-3]),
                                     encoding="utf-8")
            print(f"wrote docs/bench/{name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
