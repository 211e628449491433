"""What a reflected (or primary) ray meets and its colour: struts, the camera's body (barrel,
glass, front ring, box), chessboards; the room at infinity, the body's and the holder's shading."""

from __future__ import annotations

import math

import cv2
import numpy as np

from .optics import dot, lin


def keep_nearer(t_best, lab, c_out, t, label, colors):
    """Where ``t < t_best`` the hit at ``t`` wins: its label and colour are written into
    ``lab`` and ``c_out`` (in place); returns the new nearest distances."""
    nearer = t < t_best
    if not nearer.any():
        return t_best
    lab[nearer] = label
    c_out[nearer] = colors[nearer]
    return np.where(nearer, t, t_best)


def rod_hits(o, v, strut):
    """Entry ``t`` of unit rays on a strut's cylinder (inf where missed) and ``dist / radius``.

    Exact for the cylinder's silhouette: a ray touches it where its distance to the axis line
    equals the radius; the closest point on the axis must lie on the segment.
    """
    s0 = np.asarray(strut.start, np.float64)
    u = np.asarray(strut.end, np.float64) - s0
    length = float(np.linalg.norm(u))
    e = u / length
    w = o - s0
    bb = dot(v, e)
    d = np.einsum("ij,ij->i", v, w)
    ew = dot(w, e)
    denom = 1.0 - bb * bb
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (bb * ew - d) / denom
        s = ew + bb * t
        gap = w + t[:, None] * v - s[:, None] * e
        dist = np.linalg.norm(gap, axis=1)
        rr = strut.radius
        hit = (dist <= rr) & (s >= 0) & (s <= length) & (denom > 1e-12)
        t_in = t - np.sqrt(np.maximum(rr * rr - dist * dist, 0.0) / np.maximum(denom, 1e-300))
    ok = hit & (t_in > 1e-9)
    return np.where(ok, t_in, np.inf), dist / rr


def near_body(o, v, body):
    """Indices of camera-frame rays that pass the body's bounding sphere (ahead of them)."""
    zlo = min(0.0, body.z_box - body.depth_box)
    zc = 0.5 * (zlo + body.z_barrel)
    half = np.array([max(body.w_box, body.r_barrel), max(body.h_box, body.r_barrel)])
    rad2 = float(half @ half) + (0.5 * (body.z_barrel - zlo)) ** 2
    wx, wy, wz = -o[:, 0], -o[:, 1], zc - o[:, 2]
    tc = wx * v[:, 0] + wy * v[:, 1] + wz * v[:, 2]
    miss2 = wx * wx + wy * wy + wz * wz - tc * tc
    return np.flatnonzero((miss2 <= rad2) & (tc > 0))


def body_hits(o, v, body):
    """Nearest hit of camera-frame rays on the body: ``t`` (inf: none), part label, hit point."""
    n = len(o)
    t_best = np.full(n, np.inf)
    label = np.zeros(n, np.int8)
    with np.errstate(invalid="ignore", divide="ignore"):
        # front disc z = z_barrel, seen from the mirror side
        tf = (body.z_barrel - o[:, 2]) / v[:, 2]
        xf = o[:, 0] + tf * v[:, 0]
        yf = o[:, 1] + tf * v[:, 1]
        rho2 = xf * xf + yf * yf
        ok = (v[:, 2] < 0) & (tf > 0) & (rho2 <= body.r_barrel**2)
        t_best = np.where(ok, tf, t_best)
        label = np.where(ok, np.where(rho2 <= body.r_glass**2, 5, 6), label).astype(np.int8)
        # barrel side: x^2 + y^2 = r^2 from outside, z_box <= z <= z_barrel
        A = v[:, 0] ** 2 + v[:, 1] ** 2
        B = o[:, 0] * v[:, 0] + o[:, 1] * v[:, 1]
        Cc = o[:, 0] ** 2 + o[:, 1] ** 2 - body.r_barrel**2
        disc = B * B - A * Cc
        ts = (-B - np.sqrt(disc)) / A
        zs = o[:, 2] + ts * v[:, 2]
        ok = (
            (disc >= 0)
            & (Cc > 0)
            & (ts > 0)
            & (zs <= body.z_barrel)
            & (zs >= body.z_box)
            & (ts < t_best)
        )
        t_best = np.where(ok, ts, t_best)
        label = np.where(ok, 7, label).astype(np.int8)
        # box: slab test in axes turned by box_angle about z
        ca, sa = (
            math.cos(math.radians(body.box_angle_deg)),
            math.sin(math.radians(body.box_angle_deg)),
        )
        ob = np.stack([ca * o[:, 0] + sa * o[:, 1], -sa * o[:, 0] + ca * o[:, 1], o[:, 2]], axis=1)
        vb = np.stack([ca * v[:, 0] + sa * v[:, 1], -sa * v[:, 0] + ca * v[:, 1], v[:, 2]], axis=1)
        lo = np.array([-body.w_box, -body.h_box, body.z_box - body.depth_box])
        hi = np.array([body.w_box, body.h_box, body.z_box])
        t1 = (lo - ob) / vb
        t2 = (hi - ob) / vb
        tmin = np.fmin(t1, t2)
        tmax = np.fmax(t1, t2)
        par = vb == 0
        inside = (ob >= lo) & (ob <= hi)
        tmin = np.where(par, np.where(inside, -np.inf, np.inf), tmin)
        tmax = np.where(par, np.where(inside, np.inf, -np.inf), tmax)
        tn = tmin.max(axis=1)
        tx = tmax.min(axis=1)
        ok = (tn <= tx) & (tn > 0) & (tn < t_best)
        t_best = np.where(ok, tn, t_best)
        label = np.where(ok, 8, label).astype(np.int8)
        X = o + np.where(np.isfinite(t_best), t_best, 0.0)[:, None] * v
    return t_best, label, X


def board_hits(o, v, board):
    """Hits of rays ``o + t v`` (mirror frame, t > 0) on a :class:`Chessboard`: ``t`` (inf where
    missed) and the BGR colour of the hit (black or white square, or the white margin)."""
    Rb = cv2.Rodrigues(np.asarray(board.rvec, np.float64).reshape(3, 1))[0]
    tb = np.asarray(board.tvec, np.float64)
    nrm = Rb[:, 2]
    den = dot(v, nrm)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (float(tb @ nrm) - dot(o, nrm)) / den
        X = o + np.where(np.isfinite(t), t, 0.0)[:, None] * v
    xb = lin(X - tb, Rb.T)  # board frame: R^T (X - t)
    cols, rows = (int(c) for c in board.pattern_size)
    fx = xb[:, 0] / board.square_size
    fy = xb[:, 1] / board.square_size
    m = 1.0 + float(board.margin)
    with np.errstate(invalid="ignore"):
        hit = np.isfinite(t) & (t > 0)
        inside = hit & (fx >= -m) & (fx <= cols + m - 1) & (fy >= -m) & (fy <= rows + m - 1)
        squares = (fx >= -1) & (fx <= cols) & (fy >= -1) & (fy <= rows)
    parity = (np.floor(np.nan_to_num(fx)) + np.floor(np.nan_to_num(fy))) % 2 == 0
    col = np.where(
        (squares & parity)[:, None], np.asarray(board.black), np.asarray(board.white)
    ).astype(np.float64)
    return np.where(inside, t, np.inf), col


# -- shading -------------------------------------------------------------------------------------
def shade_room(room, d):
    """Colours (N, 3) float64 of unit directions ``d`` (mirror frame) in the room at infinity."""
    n = len(d)
    c, s = math.cos(math.radians(room.yaw_deg)), math.sin(math.radians(room.yaw_deg))
    dx = c * d[:, 0] + s * d[:, 1]  # into the room's axes (turned by -yaw)
    dy = -s * d[:, 0] + c * d[:, 1]
    dz = d[:, 2]
    dr = np.stack([dx, dy, dz], axis=1)
    lo = np.array([-room.half_x, -room.half_y, -room.floor])
    hi = np.array([room.half_x, room.half_y, room.ceiling])
    with np.errstate(divide="ignore", invalid="ignore"):
        ta = np.where(dr > 0, hi, lo) / dr
    ta[~(dr != 0)] = np.inf
    axis = np.argmin(ta, axis=1)
    rows = np.arange(n)
    t = ta[rows, axis]
    X = dr * t[:, None]
    surface = 2 * axis + (dr[rows, axis] > 0)
    u = np.where(axis == 0, X[:, 1], X[:, 0])
    v = np.where(axis == 2, X[:, 1], X[:, 2])
    table = np.asarray(room.wall_colors, np.float64)
    col = table[surface].copy()
    walls = axis < 2
    # walls: lighter towards the ceiling, a soft horizontal modulation, a dark skirting board
    hgt = (v + room.floor) / (room.floor + room.ceiling)
    shade = np.where(walls, 0.78 + 0.3 * hgt + 0.04 * np.sin(2.1 * u), 1.0)
    col *= shade[:, None]
    skirting = walls & (v < -room.floor + 0.09)
    col[skirting] = (40.0, 45.0, 55.0)
    floor = surface == 4
    if room.plank > 0:
        k = np.floor(X[floor, 0] / room.plank).astype(np.int64)
        col[floor] *= (0.85 + 0.15 * ((k * 7919) % 5) / 4.0)[:, None]
    for surf, u0, u1, v0, v1, bgr in room.rects:
        idx = np.flatnonzero(surface == surf)
        inside = (u[idx] >= u0) & (u[idx] <= u1) & (v[idx] >= v0) & (v[idx] <= v1)
        col[idx[inside]] = bgr
    label = np.full(n, 3, np.int8)
    if room.dark_floor_deg is not None:
        dark = dz < math.sin(math.radians(room.dark_floor_deg))
        col[dark] = (9.0, 10.0, 11.0) + 3.0 * np.sin(40.0 * dx[dark])[:, None]
        label[dark] = 4
    return col, label


def shade_body(body, X, label):
    """Colours of body hits (camera frame hit points ``X``, labels 5-8)."""
    col = np.zeros((len(X), 3))
    rho = np.hypot(X[:, 0], X[:, 1])
    g = label == 5
    col[g] = body.glass_color
    if g.any():
        rg = rho[g]
        cg = col[g]
        cg[rg <= body.r_aperture] = (5.0, 4.0, 4.0)
        for i, rr in enumerate(body.rings):
            band = np.abs(rg - rr) <= 0.06 * body.r_glass
            cg[band] = (38.0 + 6 * i, 36.0 + 6 * i, 40.0 + 6 * i)
            edge = np.abs(rg - rr - 0.06 * body.r_glass) <= 0.015 * body.r_glass
            cg[edge] = (95.0, 90.0, 85.0)
        for hx, hy, hr in body.highlights:
            spot = np.hypot(X[g, 0] - hx, X[g, 1] - hy) <= hr
            cg[spot] = (245.0, 245.0, 240.0)
        col[g] = cg
    f = label == 6
    if f.any():
        ang = np.arctan2(X[f, 1], X[f, 0])
        knurl = 1.0 + 0.18 * np.sign(np.sin(90.0 * ang))
        col[f] = np.asarray(body.ring_color) * knurl[:, None]
    s = label == 7
    if s.any():
        ang = np.arctan2(X[s, 1], X[s, 0])
        col[s] = np.asarray(body.side_color) * (0.85 + 0.15 * np.cos(ang))[:, None]
    b = label == 8
    if b.any():
        col[b] = (
            np.asarray(body.box_color) * (1.0 + 0.1 * np.tanh(X[b, 2] - body.z_box + 0.5))[:, None]
        )
    return col


def shade_holder(holder, X):
    """Colours of hits on the holder plate (mirror-frame points ``X``)."""
    if holder.kind == "white":
        base = np.array([232.0, 234.0, 236.0])
        return (
            np.broadcast_to(base, (len(X), 3))
            * (1.0 - 0.02 * np.cos(np.arctan2(X[:, 1], X[:, 0])))[:, None]
        )
    if holder.kind == "black":
        return np.broadcast_to(np.array([17.0, 17.0, 19.0]), (len(X), 3)).copy()
    ang = np.arctan2(X[:, 1], X[:, 0])  # metal: brushed, brightness varies with azimuth
    g = 125.0 + 55.0 * np.cos(2.0 * ang + 0.7) + 15.0 * np.cos(5.0 * ang)
    return np.stack([g, g, g * 1.03], axis=1)
