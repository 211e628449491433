"""Choosing Chen's posture by eye (one image): ``calibrate(choose=N)`` / ``--choose N`` takes
candidate N, recorded as the user's choice; ``--candidates DIR`` writes their panoramas."""

from __future__ import annotations

import cv2
import pytest

import omnicam
from omnicam import synthetic
from omnicam.calibration import calibrate
from omnicam.cli import main
from omnicam.formats.intrinsics import write_intrinsics
from omnicam.synthetic.demo import demo_environment


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    folder = tmp_path_factory.mktemp("choose")
    truth = synthetic.misaligned_rig(3.0, 30.0, (1.5, -1.0, 1.0), image_size=(400, 400))
    image = synthetic.render_environment(truth, demo_environment(), supersample=2, seed=1)
    path = folder / "mirror.png"
    cv2.imwrite(str(path), image)
    write_intrinsics(folder / "k.yaml", truth.K, None, truth.image_size)
    _, report = calibrate(truth.K, truth.mirror, image=image)
    physical = [i for i, c in enumerate(report.candidates) if c.physical]
    impossible = [i for i, c in enumerate(report.candidates) if not c.physical]
    other = next(i for i in physical if i != report.chosen)
    return {
        "truth": truth,
        "image": image,
        "path": str(path),
        "k": str(folder / "k.yaml"),
        "chosen": report.chosen,
        "other": other,
        "impossible": impossible,
    }


def test_the_users_choice_is_taken_and_recorded(scene):
    truth = scene["truth"]
    _, report = calibrate(
        truth.K,
        truth.mirror,
        image=scene["image"],
        choose=scene["other"],
    )
    assert report.chosen == scene["other"]
    assert report.steps["selection"].chosen_by == "user"
    assert report.confidence == 0.0 and not report.ambiguous  # the cues chose another
    note = f"candidate {scene['other']} chosen by the user; the cues chose {scene['chosen']}"
    assert any(w.startswith(note) for w in report.warnings)


def test_an_impossible_candidate_cannot_be_chosen(scene):
    truth = scene["truth"]
    bad = scene["impossible"][0]
    with pytest.raises(ValueError, match=f"candidate {bad} is not physically possible"):
        calibrate(
            truth.K,
            truth.mirror,
            image=scene["image"],
            choose=bad,
        )


def test_cli_writes_the_candidates_panoramas_and_records_the_choice(scene, tmp_path, capsys):
    folder = tmp_path / "cands"
    calib = tmp_path / "rig.yaml"
    args = ["calibrate", scene["path"], "--intrinsics", scene["k"]]
    args += ["--mirror", "23.4", "28.1", "30", "-o", str(calib), "--candidates", str(folder)]
    assert main([*args, "--choose", str(scene["other"])]) == 0
    out = capsys.readouterr().out
    for i in range(4):
        path = folder / f"candidate_{i}.jpg"
        assert path.exists() == (i not in scene["impossible"])
        if path.exists():
            assert cv2.imread(str(path)) is not None and f"wrote {path}" in out
    assert f"candidate {scene['impossible'][0]}: no panorama" in out
    verdict = omnicam.read_verdict(calib)
    assert any(f"candidate {scene['other']} chosen by the user" in w for w in verdict.warnings)
    assert verdict.confidence == 0.0
    # the panoramas are not replaced without --overwrite, before any work
    assert main([*args[:-4], "-o", str(tmp_path / "b.yaml"), "--candidates", str(folder)]) == 1
    assert "candidate_0.jpg exists; pass --overwrite" in capsys.readouterr().err
