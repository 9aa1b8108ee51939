"""A student's engine, as the course's last exercise writes it: explicit Euler, contacts
tested where each step ends, the seed's impulse and reflection. ``flip`` gets the impulse's
sign wrong. It exports its run in physdbg's foreign-run formats (docs/foreign-runs.md)."""

from __future__ import annotations

import json

import numpy as np


def simulate(scene, steps: int, dt: float, flip: bool = False):
    """(times (F,), positions (F, N, 3), velocities (F, N, 3)) of a physdbg Scene."""
    st, walls = scene.state, scene.walls
    x, v = st.positions.copy(), st.velocities.copy()
    inv, r, e = st.inverse_mass, st.radius, st.restitution
    g = np.asarray(scene.settings.gravity)
    times, xs, vs = [0.0], [x.copy()], [v.copy()]
    for k in range(1, steps + 1):
        x = x + v * dt  # P_new = P_old + v t
        v = v + g * (inv > 0)[:, None] * dt
        for n, d, two in zip(walls.normals, walls.offsets, walls.two_sided, strict=True):
            gap = x @ n - d
            side = np.sign(gap) if two else np.ones_like(gap)
            hit = (np.abs(gap) < r) if two else (gap < r)
            for i in np.flatnonzero(hit & (inv > 0)):
                normal = side[i] * n
                if v[i] @ normal < 0:  # reflect: v - (1 + e)(v·n) n
                    v[i] = v[i] - (1 + e[i]) * (v[i] @ normal) * normal
        for a in range(len(r)):
            for b in range(a + 1, len(r)):
                delta = x[a] - x[b]
                dist = float(np.linalg.norm(delta))
                if dist < r[a] + r[b] and inv[a] + inv[b] > 0:
                    n = delta / dist
                    closing = (v[a] - v[b]) @ n
                    if closing < 0:
                        j = -(1 + min(e[a], e[b])) * closing / (inv[a] + inv[b])
                        if flip:
                            j = -j
                        v[a] += j * inv[a] * n
                        v[b] -= j * inv[b] * n
        times.append(k * dt)
        xs.append(x.copy())
        vs.append(v.copy())
    return np.array(times), np.array(xs), np.array(vs)


def write_csv(path, times, xs, vs=None) -> None:
    with open(path, "w") as f:
        f.write("step,time,body,x,y,z" + (",vx,vy,vz" if vs is not None else "") + "\n")
        for k, t in enumerate(times):
            for i, p in enumerate(xs[k]):
                row = [k, repr(float(t)), i, *map(repr, map(float, p))]
                if vs is not None:
                    row += list(map(repr, map(float, vs[k][i])))
                f.write(",".join(map(str, row)) + "\n")


def write_jsonl(path, times, xs, vs=None) -> None:
    with open(path, "w") as f:
        for k, t in enumerate(times):
            record = {"step": k, "time": float(t), "positions": xs[k].tolist()}
            if vs is not None:
                record["velocities"] = vs[k].tolist()
            f.write(json.dumps(record) + "\n")
