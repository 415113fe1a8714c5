"""The HTML report as a person sees it: headless Chromium renders report.html of a seed_rig
run and of the bearing example to PNG; the page must not be blank, every figure must load,
and the header, tables and figures must be where the layout puts them.

Slow (an end-to-end run plus a browser start): ``python -m pytest -m slow tests/report``.
Needs Debian's ``chromium`` (``apt-get install -y chromium``); skipped without it.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.slow

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
CHROMIUM = shutil.which("chromium") or ("/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None)
WIDTH, HEIGHT = 1280, 4000
HEADER_RGB = (0x1F, 0x3A, 0x5F)          # header background in pipeline/report/html.py
PAGE_RGB = (0xF6, 0xF7, 0xF9)            # page background there


def _screenshot(html: Path, png: Path, tmp: Path, height: int = HEIGHT) -> np.ndarray:
    from PIL import Image

    if CHROMIUM is None:
        pytest.skip("headless render check needs Debian's chromium (/usr/bin/chromium): "
                    "apt-get install -y chromium")
    profile = tmp / "chromium-profile"
    profile.mkdir(exist_ok=True)
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
           "--no-first-run", "--disable-background-networking", "--disable-component-update",
           "--disable-sync", f"--user-data-dir={profile}", f"--screenshot={png}",
           f"--window-size={WIDTH},{height}", html.resolve().as_uri()]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    assert png.is_file(), f"chromium wrote no screenshot (exit {r.returncode}): {r.stderr[-2000:]}"
    return np.asarray(Image.open(png).convert("RGB"), dtype=np.int16)


def _run(scene_text: str, name: str, d: Path) -> Path:
    from meshphase.run.scene import parse_scene
    from meshphase.run.stages import new_output_dir, run_scene, write_outputs

    scene = parse_scene(scene_text, d / f"{name}.toml")
    ctx = run_scene(scene)
    files = write_outputs(ctx, new_output_dir(d / f"{name}-out"))
    return files["report"]


@pytest.fixture(scope="module")
def rig_report(tmp_path_factory):
    d = tmp_path_factory.mktemp("render_rig")
    text = (EXAMPLES / "rig_validation.toml").read_text(encoding="utf-8")
    text = text.replace("minutes = 1.0", "minutes = 0.5").replace("samples = 4096", "samples = 256")
    return _run(text, "rig", d), d


def _rows_with_content(img: np.ndarray) -> np.ndarray:
    """Boolean per pixel row: does the row show anything but one flat colour?"""
    return img.std(axis=(1, 2)) > 1.0


def test_rig_report_renders(rig_report):
    html, d = rig_report
    img = _screenshot(html, d / "rig.png", d)
    assert img.shape == (HEIGHT, WIDTH, 3)
    assert img.std() > 20.0                              # not blank
    # the dark header band across the top
    top = img[10:60, 20:WIDTH - 20].reshape(-1, 3)
    assert np.mean(np.all(np.abs(top - HEADER_RGB) <= 3, axis=1)) > 0.8
    # content all the way down the first 4000 px (the report is longer: sections, tables
    # and figures leave no stretch of more than 300 px of empty rows)
    rows = _rows_with_content(img[100:])
    runs = np.diff(np.flatnonzero(np.r_[True, rows, True]))
    assert runs.max() < 300, f"an empty band of {runs.max()} px"
    # figures are drawn (white plot areas with dark lines), so many distinct colours appear
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 500


def test_rig_report_figures_load(rig_report):
    """Every embedded figure decodes to a picture that is not one flat colour."""
    import base64
    import io
    import re

    from PIL import Image

    html, _ = rig_report
    text = html.read_text(encoding="utf-8")
    pngs = re.findall(r'src="data:image/png;base64,([^"]+)"', text)
    assert len(pngs) >= 6             # quality, 2 onset plots, phasing, residuals, load sharing, stage times
    for b in pngs:
        im = np.asarray(Image.open(io.BytesIO(base64.b64decode(b))).convert("L"), dtype=float)
        assert im.std() > 5.0
        assert im.shape[1] <= 2200    # no figure so wide the page must scale its text to nothing


def test_bearing_report_renders(tmp_path):
    html = _run((EXAMPLES / "bearing_moments.toml").read_text(encoding="utf-8"), "bearing", tmp_path)
    img = _screenshot(html, tmp_path / "bearing.png", tmp_path, height=1800)
    assert img.std() > 20.0
    rows = _rows_with_content(img[:1200])
    assert rows.mean() > 0.5          # tables and the GSAM figure fill the first screen
    # no table or figure pushes past the section boxes: below the header and the nav bar the
    # strip right of the boxes (max-width 1200 px + margins) shows only the page background
    strip = img[140:, WIDTH - 40:WIDTH - 20].reshape(-1, 3)
    assert np.all(np.abs(strip - PAGE_RGB) <= 2)
