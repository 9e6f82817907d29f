"""FlyAgent observations (docs/model/agents.md §6) written by kernels into one preallocated float buffer.

Layout per (env, drone, frame): the 9 own features, then N neighbour slots x 4, then the N-slot validity
mask (1.0 / 0.0). The env exposes torch views of this one buffer (``agent``, ``neighbors``,
``neighbors_mask``), so a step passes one observation tensor to the kernel and copies nothing.
Frame 0 is the newest.
"""

import taichi as ti

OWN_FEATURES = 9


def frame_width(num_drones: int) -> int:
    """Floats per frame: own features, neighbour slots and their mask."""
    return OWN_FEATURES + 5 * num_drones


@ti.func
def own_features(drone_id: ti.i32, v, p, g, v_max: ti.f32, s: ti.f32):
    """The 9 features of docs/model/agents.md §6: id, velocity, goal delta, heading cos/sin, speed, distance."""
    vn = ti.math.clamp(v / (v_max * s), -1.0, 1.0)
    delta = g - p
    dg = ti.math.clamp(delta / s, -1.0, 1.0)
    dist = delta.norm()
    speed = v.norm()
    cos_h = 0.0
    sin_h = 0.0
    if dist < 1e-8:
        cos_h = 1.0
    elif speed >= 1e-8:
        ug = delta / dist
        uv = v / speed
        cos_h = ti.math.clamp(uv.dot(ug), -1.0, 1.0)
        sin_h = ti.math.clamp(uv[0] * -ug[1] + uv[1] * ug[0], -1.0, 1.0)
    return ti.Vector([ti.cast(drone_id, ti.f32), vn[0], vn[1], dg[0], dg[1], cos_h, sin_h,
                      ti.min(speed / v_max, 1.0), ti.min(dist / s, 1.0)])


@ti.func
def write_frame(obs: ti.template(), drones: ti.template(), e, d, t):
    """Write drone d's current frame into obs[e, d, t, :]."""
    f = own_features(d, drones.vel[e, d], drones.pos[e, d] / drones.cell, drones.goal[e, d], drones.v_max,
                     drones.s_norm)
    for k in ti.static(range(OWN_FEATURES)):
        obs[e, d, t, k] = f[k]
    n = drones.num_drones
    for j in range(n):
        nb = drones.neighbours[e, d, j]
        for k in ti.static(range(4)):
            obs[e, d, t, OWN_FEATURES + 4 * j + k] = nb[k]
        obs[e, d, t, OWN_FEATURES + 4 * n + j] = ti.cast(drones.neighbour_mask[e, d, j], ti.f32)


@ti.func
def push_frame(obs: ti.template(), drones: ti.template(), e, d, frames: ti.template()):
    """Shift the stack one frame older and write the newest frame at index 0."""
    for t in ti.static(range(frames - 1, 0, -1)):
        for k in range(obs.shape[3]):
            obs[e, d, t, k] = obs[e, d, t - 1, k]
    write_frame(obs, drones, e, d, 0)


@ti.func
def fill_frames(obs: ti.template(), drones: ti.template(), e, d, frames: ti.template()):
    """At reset the stack holds copies of the initial frame (a loop, not an unroll: one copy of the frame code in
    the reset kernel instead of one per stacked frame compiles faster)."""
    for t in range(frames):
        write_frame(obs, drones, e, d, t)
