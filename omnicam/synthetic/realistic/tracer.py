"""The tracer: pixel samples to what they see (labels, colours, mirror points and reflected
directions), in chunks; :func:`trace`."""

from __future__ import annotations

import math

import numpy as np

from .optics import CameraNumbers, camera_rays, intersect_mirror, lin, mirror_normal, reflect
from .scene import Rig
from .surfaces import (
    board_hits,
    body_hits,
    keep_nearer,
    near_body,
    rod_hits,
    shade_body,
    shade_holder,
    shade_room,
)

_CHUNK = 1 << 18  # samples traced per chunk


def _trace_chunk(num, rig, pixels):
    """Trace pixel samples: labels (N,), colours (N, 3), mirror points P and reflected d."""
    n = len(pixels)
    label = np.zeros(n, np.int8)
    col = np.zeros((n, 3))
    vc = camera_rays(num.K, num.D, pixels)
    V = lin(vc, num.R.T)  # V_M = R^T V_C  (eq. 16)
    O = np.broadcast_to(num.C, V.shape)
    t_m = intersect_mirror(num.a, num.b, num.rim, O, V)
    hit = np.isfinite(t_m)
    on_mirror = hit.copy()
    t_prim = np.where(hit, t_m, np.inf)
    # holder plate in the rim plane (only where the mirror is missed)
    if rig.holder is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            th = (num.z_rim - num.C[2]) / V[:, 2]
        Xh = num.C + np.where(np.isfinite(th), th, 0.0)[:, None] * V
        ca = math.cos(math.radians(rig.holder.angle_deg))
        sa = math.sin(math.radians(rig.holder.angle_deg))
        e1 = (ca * Xh[:, 0] + sa * Xh[:, 1]) / rig.holder.outer_axes[0]
        e2 = (-sa * Xh[:, 0] + ca * Xh[:, 1]) / rig.holder.outer_axes[1]
        on = (
            ~hit
            & (th > 0)
            & (e1 * e1 + e2 * e2 <= 1.0)
            & (Xh[:, 0] ** 2 + Xh[:, 1] ** 2 >= num.rim**2)
        )
        label[on] = 1
        col[on] = shade_holder(rig.holder, Xh[on])
        t_prim = np.where(on, th, t_prim)
    # struts seen directly, in front of the mirror or the holder
    for strut in rig.struts:
        ts, q = rod_hits(O, V, strut)
        front = ts < t_prim
        if front.any():
            label[front] = 2
            col[front] = (
                np.asarray(strut.color)
                * (0.7 + 0.3 * np.sqrt(np.clip(1.0 - q[front] ** 2, 0.0, 1.0)))[:, None]
            )
            t_prim = np.where(front, ts, t_prim)
            hit &= ~front
    P = np.full((n, 3), np.nan)
    d = np.full((n, 3), np.nan)
    idx = np.flatnonzero(hit)
    if len(idx):
        Pm = num.C + t_m[idx, None] * V[idx]
        dm = reflect(V[idx], mirror_normal(num.a, num.b, Pm))
        dm /= np.linalg.norm(dm, axis=1, keepdims=True)
        P[idx], d[idx] = Pm, dm
        t_best = np.full(len(idx), np.inf)
        lab = np.zeros(len(idx), np.int8)
        c_out = np.zeros((len(idx), 3))
        if rig.body is not None:
            oc = lin(Pm, num.R) + num.t  # camera frame
            vcam = lin(dm, num.R)
            near = near_body(oc, vcam, rig.body)
            tb, lb, Xb = body_hits(oc[near], vcam[near], rig.body)
            got = np.isfinite(tb)
            t_best[near] = tb
            lab[near[got]] = lb[got]
            c_out[near[got]] = shade_body(rig.body, Xb[got], lb[got])
        for strut in rig.struts:
            ts, q = rod_hits(Pm, dm, strut)
            shade = (
                np.asarray(strut.color)
                * (0.7 + 0.3 * np.sqrt(np.clip(1.0 - q**2, 0.0, 1.0)))[:, None]
            )
            t_best = keep_nearer(t_best, lab, c_out, ts, 9, shade)
        for board in rig.boards:
            tb, cb = board_hits(Pm, dm, board)
            t_best = keep_nearer(t_best, lab, c_out, tb, 10, cb)
        sky = ~np.isfinite(t_best)
        if sky.any():
            c_sky, l_sky = shade_room(rig.room, dm[sky])
            c_out[sky] = c_sky
            lab[sky] = l_sky
        label[idx] = lab
        col[idx] = c_out * rig.mirror_gain
    return label, col, P, d, on_mirror


def trace_many(num, rig, pixels):
    """:func:`_trace_chunk` over chunks: labels, colours and the on-mirror flags."""
    out = [_trace_chunk(num, rig, pixels[i : i + _CHUNK]) for i in range(0, len(pixels), _CHUNK)]
    return tuple(np.concatenate([o[j] for o in out]) for j in (0, 1, 4))


def trace(camera, pixels, rig=None):
    """Trace pixels through the rig with this module's own tracer.

    Parameters
    ----------
    camera : MisalignedHyperbolicCamera
        The truth camera, read as numbers only.
    pixels : (N, 2) array_like
    rig : Rig or None
        ``None``: a bare mirror in the default room.

    Returns
    -------
    labels : (N,) int8 ndarray
        :data:`LABELS` of what each ray finally meets.
    colors : (N, 3) float64 ndarray
        BGR before the background is added (background samples are 0).
    origins, directions : (N, 3) float64 ndarrays
        Mirror points and unit reflected directions (mirror frame); NaN where the primary ray
        does not reach the mirror (missed, or occluded by a strut).
    """
    num = CameraNumbers(camera)
    rig = Rig() if rig is None else rig
    pix = np.asarray(pixels, np.float64).reshape(-1, 2)
    out = [_trace_chunk(num, rig, pix[i : i + _CHUNK])[:4] for i in range(0, len(pix), _CHUNK)]
    if not out:
        return np.zeros(0, np.int8), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3))
    return tuple(np.concatenate(parts) for parts in zip(*out))
