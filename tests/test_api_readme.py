"""The README's "Python API" example runs as written (matplotlib on the Agg backend)."""

import re
from pathlib import Path

import matplotlib

README = Path(__file__).resolve().parents[1] / "README.md"


def readme_example() -> str:
    """The first ```python block of the README's "## Python API" section, verbatim."""
    text = README.read_text(encoding="utf-8")
    section = text.split("\n## Python API\n", 1)
    assert len(section) == 2, "README has no '## Python API' section"
    body = section[1].split("\n## ", 1)[0]
    m = re.search(r"```python\n(.*?)```", body, re.S)
    assert m, "the Python API section has no ```python block"
    return m.group(1)


def test_readme_example_runs(tmp_path, monkeypatch):
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    monkeypatch.chdir(tmp_path)
    ns: dict = {"__name__": "readme_example"}
    try:
        exec(compile(readme_example(), str(README), "exec"), ns)
    finally:
        plt.close("all")
    res = ns["res"]
    assert res.status == "ok"
    assert set(res.phasing["gauge"]) == {"sun", "ring"}
    assert (tmp_path / "rig-meshphase" / "summary.json").is_file()
    assert (tmp_path / "rig-meshphase" / "report.html").is_file()
    assert ns["files"]["summary"] == tmp_path / "rig-meshphase" / "summary.json"


def test_readme_example_is_extracted():
    code = readme_example()
    for call in ("meshphase.read(", "meshphase.process(", ".plot(", ".write("):
        assert call in code
