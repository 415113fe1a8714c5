"""``meshphase campaign --recursive`` (issue 12 item 6): recordings in subfolders are found;
hidden folders, symbolic links to folders and meshphase's own output folders are not
entered; without the flag only a folder's own files count, as before."""

from __future__ import annotations

from pathlib import Path

import pytest

import meshphase.campaign.runner as cp
import meshphase.cli as cli

H5 = b"\x89HDF\r\n\x1a\n" + b"\0" * 64     # an HDF5 file by content


def _tree(tmp_path: Path) -> Path:
    d = tmp_path / "rig"
    for sub in ("day1", "day2/run_a", ".cache", "old-out"):
        (d / sub).mkdir(parents=True)
    (d / "top.h5").write_bytes(H5)
    (d / "day1" / "x.h5").write_bytes(H5)
    (d / "day1" / "notes.txt").write_text("hello")
    (d / "day2" / "run_a" / "x.h5").write_bytes(H5)
    (d / "day2" / "run_a" / "x.h5.truth.json").write_text("{}")
    (d / ".cache" / "c.h5").write_bytes(H5)
    (d / "old-out" / ".meshphase.json").write_text("{}")
    (d / "old-out" / "passes_sun.csv").write_text("a,b\n1,2\n")
    (d / "link").symlink_to(d / "day1", target_is_directory=True)
    return d


def test_recursive_finds_subfolders_in_name_order(tmp_path):
    d = _tree(tmp_path)
    files, skipped = cp.collect_recordings([d], recursive=True)
    assert [f.relative_to(d.resolve()).as_posix() for f in files] == [
        "day1/x.h5", "day2/run_a/x.h5", "top.h5"]
    reasons = {Path(s["path"]).name: s["reason"] for s in skipped}
    assert reasons[".cache"] == "hidden folder"
    assert reasons["old-out"] == "meshphase output folder"
    assert reasons["link"] == "symbolic link to a folder (not followed)"
    assert reasons["x.h5.truth.json"] == "truth sidecar"
    assert reasons["notes.txt"].startswith("not a recording")
    # the same stems in two folders still get distinct output names
    assert cp.recording_names(files) == ["x_day1", "x_run_a", "top"]


def test_without_recursive_behaviour_stays(tmp_path):
    d = _tree(tmp_path)
    files, skipped = cp.collect_recordings([d])
    assert [f.name for f in files] == ["top.h5"]
    reasons = {Path(s["path"]).name: s["reason"] for s in skipped}
    assert reasons["day1"] == reasons["day2"] == reasons[".cache"] == "not a file"


def test_recursive_empty_and_bad_input(tmp_path):
    assert cp.collect_recordings([], recursive=True) == ([], [])
    (tmp_path / "empty" / "deeper").mkdir(parents=True)
    assert cp.collect_recordings([tmp_path / "empty"], recursive=True) == ([], [])
    with pytest.raises(TypeError, match="single path"):
        cp.collect_recordings(str(tmp_path), recursive=True)
    with pytest.raises(FileNotFoundError):
        cp.collect_recordings([tmp_path / "missing"], recursive=True)


def test_cli_passes_recursive(monkeypatch, tmp_path, capsys):
    seen = {}

    def fake(scene, inputs, **kw):
        seen.update(kw, inputs=inputs)
        return {"scene": "s", "counts": {"ok": 0, "unreliable": 0, "partial": 0, "failed": 0},
                "timing_s": {"total": 0.0}, "cluster": {"n_workers": 1, "scheduler": "x"},
                "resume": {"enabled": False}, "recordings": [], "files": {}, "exit_code": 0}

    monkeypatch.setattr(cp, "cli_campaign", fake)
    scene = tmp_path / "s.toml"
    scene.write_text("")
    assert cli.main(["-q", "campaign", str(scene), str(tmp_path), "--recursive"]) == 0
    assert seen["recursive"] is True and seen["inputs"] == [str(tmp_path)]
    assert cli.main(["-q", "campaign", str(scene), str(tmp_path)]) == 0
    assert seen["recursive"] is False


def test_run_campaign_refuses_no_recording_found_recursively(tmp_path):
    # the recursive search feeds the same "no recording files found" check
    from seed_rig_toml import SEED_RIG_GEARSET

    (tmp_path / "in" / "sub").mkdir(parents=True)
    scene = tmp_path / "s.toml"
    scene.write_text('results = ["phasing"]\n' + SEED_RIG_GEARSET
                     + '[input]\nsynthetic = "seed_rig"\nminutes = 0.05\n')
    with pytest.raises(ValueError, match="no recording files found"):
        cp.run_campaign(scene, [tmp_path / "in"], tmp_path / "out", recursive=True)
