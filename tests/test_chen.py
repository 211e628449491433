"""Chen's conic method (paper section 3.1 and appendix): four candidates, one of them exact."""

import conftest
import numpy as np
import pytest
from conftest import RANDOM_RIGS as RIGS
from conftest import axis_angle_deg, candidates_of

from omnicam import HyperbolicMirror, synthetic
from omnicam.calibration import chen


def test_rim_conic_passes_through_the_rim_image():
    for cam in RIGS[:10]:
        Q = chen.rim_conic(cam.K, cam.R, cam.tvec, cam.mirror)
        x = np.concatenate([cam.rim_image_points(90), np.ones((90, 1))], axis=1)
        scale = np.abs(np.einsum("ij,jk,ik->i", x, Q, x)).max()
        assert scale < 1e-12


def test_exact_conic_gives_the_true_posture_among_four_candidates():
    worst_axis = worst_origin = 0.0
    for cam in RIGS:
        cands = candidates_of(cam)
        assert len(cands) == 4
        errs = [
            (axis_angle_deg(c.axis, cam.R[:, 2]), np.linalg.norm(c.tvec - cam.tvec)) for c in cands
        ]
        best = min(range(4), key=lambda i: errs[i][0] + errs[i][1])
        assert cands[best].physical
        worst_axis = max(worst_axis, errs[best][0])
        worst_origin = max(worst_origin, errs[best][1])
        # the candidate's rvec is the camera's rvec (same gauge)
        assert np.allclose(cands[best].rvec, cam.rvec, atol=1e-9)
    assert worst_axis < 1e-6  # degrees
    assert worst_origin < 1e-6  # mm


def test_two_candidates_are_physical_and_two_face_away():
    for cam in RIGS[:30]:
        cands = candidates_of(cam)
        phys = [c for c in cands if c.physical]
        assert len(phys) == 2
        for c in cands:
            if not c.physical:
                assert any("facing away" in r for r in c.reasons)
            else:
                assert c.reasons == ()
                # axis away from the camera, rim in front, camera below the mirror
                assert c.rim_centre @ c.axis > 0 and c.rim_centre[2] > 0


def test_candidates_l_m_and_l1_m1_share_the_rim_and_have_opposite_axes():
    for cam in RIGS[:10]:
        c = {(x.l, x.m): x for x in candidates_of(cam)}
        for l, m in ((0, 0), (0, 1)):
            a, b = c[(l, m)], c[(1 - l, 1 - m)]
            assert np.allclose(a.rim_centre, b.rim_centre, atol=1e-9)
            assert np.allclose(a.axis, -b.axis, atol=1e-12)


def test_conic_scale_and_sign_do_not_matter():
    cam = RIGS[0]
    Q_I = chen.rim_conic(cam.K, cam.R, cam.tvec, cam.mirror)
    ref = chen.chen_candidates(chen.normalized_conic(Q_I, cam.K), cam.mirror)
    for s in (-1.0, 1e-6, -3e4):
        other = chen.chen_candidates(chen.normalized_conic(s * Q_I, cam.K), cam.mirror)
        for a, b in zip(ref, other):
            assert np.allclose(a.tvec, b.tvec, atol=1e-9) and np.allclose(
                a.rvec, b.rvec, atol=1e-12
            )


def test_normalized_conic_has_one_negative_eigenvalue_and_positive_block():
    cam = RIGS[1]
    Qe = chen.normalized_conic(-chen.rim_conic(cam.K, cam.R, cam.tvec, cam.mirror), cam.K)
    lam = np.linalg.eigvalsh(Qe)
    assert np.count_nonzero(lam < 0) == 1
    assert np.linalg.det(Qe[:2, :2]) > 0 and Qe[0, 0] > 0
    assert np.isclose(np.linalg.norm(Qe), 1.0)


def test_aligned_rig_gives_rvec_zero_and_tvec_at_the_focus():
    cam = synthetic.aligned_rig()
    for c in candidates_of(cam):
        if c.physical:  # both physical candidates coincide on the axis
            assert np.allclose(c.rvec, 0.0, atol=1e-7)
            assert np.allclose(c.tvec, [0.0, 0.0, cam.mirror.c], atol=1e-6)


def test_skewed_K_gives_the_true_posture():
    cam = conftest.RIGS["skew"]  # skew 0.8, fy 2 % longer than fx
    errs = [
        np.linalg.norm(c.tvec - cam.tvec) + axis_angle_deg(c.axis, cam.R[:, 2])
        for c in candidates_of(cam)
    ]
    assert min(errs) < 1e-8


def test_hyperbola_conic_raises():
    K = synthetic.aligned_rig().K
    hyperbola = np.diag([1.0, -1.0, -100.0])
    with pytest.raises(ValueError, match="not an ellipse"):
        chen.normalized_conic(hyperbola, K)


def test_imaginary_and_degenerate_conics_raise():
    K = synthetic.aligned_rig().K
    with pytest.raises(ValueError, match="imaginary"):
        chen.normalized_conic(np.diag([1.0, 1.0, 1.0]), K)
    with pytest.raises(ValueError, match="degenerate"):
        chen.normalized_conic(np.diag([1.0, -1.0, 0.0]), K)
    with pytest.raises(ValueError, match="zero"):
        chen.normalized_conic(np.zeros((3, 3)), K)
    with pytest.raises(ValueError, match="3x3"):
        chen.normalized_conic(np.eye(2), K)


def test_singular_K_raises():
    K = np.array([[100.0, 0.0, 50.0], [0.0, 0.0, 50.0], [0.0, 0.0, 1.0]])
    with pytest.raises(ValueError, match="non-singular"):
        chen.normalized_conic(np.diag([1.0, 1.0, -1.0]), K)


def test_candidates_need_a_mirror():
    with pytest.raises(ValueError, match="HyperbolicMirror"):
        chen.chen_candidates(np.diag([1.0, 1.0, -1.0]), None)


def test_physical_reasons_flag_a_camera_above_the_mirror():
    m = HyperbolicMirror(23.4, 28.1, 30.0)
    R = np.diag([1.0, -1.0, -1.0])  # mirror upside down: the camera sees its back
    reasons = chen.physical_reasons(R, np.array([0.0, 0.0, 200.0]), m)
    assert "mirror facing away (axis points towards the camera)" in reasons
    assert "camera not below the mirror" in reasons
    reasons = chen.physical_reasons(np.eye(3), np.array([0.0, 0.0, -200.0]), m)
    assert "rim behind the camera" in reasons
