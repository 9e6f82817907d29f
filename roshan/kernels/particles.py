"""Convection and radiation particles (docs/model/fire.md §7): pure ``ti.func``s on particle records, and the
passes over one env's particle pools (motion, emission, removal under water) that the fire update runs.

Records are f32 vectors so a particle is one contiguous load and store in the serial per-env pass. The pool
passes take the simulator as ``ti.template()`` (a :class:`roshan.kernels.fire.FireSim`) and use its pools,
counters, random tables and compile-time constants; a particle's cell and its visit are the simulator's
(``cell_of``, ``visit``), since a visit writes a cell record.
"""


import taichi as ti

from roshan.kernels import rng
from roshan.kernels.fire_records import N_CONV, N_DROP_CONV, N_DROP_RAD, N_RAD

# Convection record: position (m), velocity (m/s), intensity.
P_X1, P_X2, P_U1, P_U2, P_Y = range(5)
CONV_FIELDS = 5
# Radiation record: origin (m), radius (m), direction (cos, sin), intensity, per-update decay factor, class.
R_O1, R_O2, R_R, R_C, R_S, R_Y, R_DECAY, R_CLS = range(8)
RAD_FIELDS = 8


@ti.func
def advect_convection(p, wind, n1: ti.f32, n2: ti.f32, decay: ti.f32, f1dt: ti.f32, f2: ti.f32, fldt: ti.f32):
    """One Langevin update: Y decays, then per component U relaxes to the wind with noise and X follows U.

    ``U_i <- U_i - f1 (U_i - U_w,i) dt + f2 N_i``; ``X_i <- X_i + F_l U_i dt`` (with the new U_i).
    """
    u1 = p[P_U1] - f1dt * (p[P_U1] - wind[0]) + f2 * n1
    u2 = p[P_U2] - f1dt * (p[P_U2] - wind[1]) + f2 * n2
    return ti.Vector([p[P_X1] + fldt * u1, p[P_X2] + fldt * u2, u1, u2, p[P_Y] * decay], ti.f32)


@ti.func
def advect_radiation(p, rot, n_r: ti.f32, sf_mean_dt: ti.f32, sf_std_sqrt_dt: ti.f32):
    """One radiation update: the angle takes a N(0, (2 pi)^2) kick, the radius a drift plus noise.

    The angle is kept as a unit vector; ``rot`` = (cos 2 pi N, sin 2 pi N) rotates it (phi += 2 pi N) and a
    first-order renormalisation stops float drift over the ~1700 updates of a particle's life.
    """
    c = p[R_C] * rot[0] - p[R_S] * rot[1]
    s = p[R_C] * rot[1] + p[R_S] * rot[0]
    norm = 1.5 - 0.5 * (c * c + s * s)
    r = p[R_R] + sf_mean_dt + sf_std_sqrt_dt * n_r
    return ti.Vector([p[R_O1], p[R_O2], r, c * norm, s * norm, p[R_Y] * p[R_DECAY], p[R_DECAY], p[R_CLS]], ti.f32)


@ti.func
def radiation_position(p):
    """Current position X = X_mc + r (cos phi, sin phi), metres."""
    return ti.Vector([p[R_O1] + p[R_R] * p[R_C], p[R_O2] + p[R_R] * p[R_S]])


@ti.func
def new_radiation(o1: ti.f32, o2: ti.f32, y_st: ti.f32, decay: ti.f32, cls: ti.i32):
    """A radiation particle at its origin: r = 0, phi = 0."""
    return ti.Vector([o1, o2, 0.0, 1.0, 0.0, y_st, decay, ti.cast(cls, ti.f32)], ti.f32)


# ------------------------------------------------------------------------------------------ pools of one env


@ti.func
def move_convection(sim: ti.template(), e, t, step_key):
    """Update t of env e's convection particles, in pool order (a particle's draws are keyed by its index):
    one still over the grid and above y_lim keeps its place in the closed-up pool and visits its cell."""
    w = 0
    wind = sim.wind[e]
    for i in range(sim.counts[e, N_CONV]):
        h = rng.key(step_key, i, rng.DOMAIN_CONVECTION)
        p = advect_convection(sim.conv[e, i], wind, sim.normals[rng.low16(h)], sim.normals[rng.high16(h)],
                              sim.conv_decay, sim.conv_f1dt, sim.conv_f2, sim.conv_fldt)
        c = sim.cell_of(p[P_X1], p[P_X2])
        if c >= 0 and p[P_Y] >= sim.conv_y_lim:
            sim.conv[e, w] = p
            w += 1
            sim.visit(e, c, t)
    sim.counts[e, N_CONV] = w


@ti.func
def move_radiation(sim: ti.template(), e, t, step_key):
    """move_convection for radiation particles, each spreading at the rate of the class that emitted it."""
    w = 0
    for i in range(sim.counts[e, N_RAD]):
        h = rng.key(step_key, i, rng.DOMAIN_RADIATION)
        p = sim.rad[e, i]
        sf = sim.cls_sf[ti.cast(p[R_CLS], ti.i32)]
        p = advect_radiation(p, sim.unit[rng.low16(h)], sim.normals[rng.high16(h)], sf[0] * sim.dt,
                             sf[1] * sim.sqrt_dt)
        x = radiation_position(p)
        c = sim.cell_of(x[0], x[1])
        if c >= 0 and p[R_Y] >= sim.rad_y_lim:
            sim.rad[e, w] = p
            w += 1
            sim.visit(e, c, t)
    sim.counts[e, N_RAD] = w


@ti.func
def emit_convection(sim: ti.template(), e, c, step_key):
    """Burning cell c's convection particle joins env e's pool, or is counted as dropped if the pool is full."""
    n = sim.counts[e, N_CONV]
    if n < sim.conv_capacity:
        sim.conv[e, n] = convection_from(sim, c, step_key)
        sim.counts[e, N_CONV] = n + 1
    else:
        sim.counts[e, N_DROP_CONV] += 1


@ti.func
def emit_radiation(sim: ti.template(), e, c, step_key):
    """emit_convection for a radiation particle."""
    n = sim.counts[e, N_RAD]
    if n < sim.rad_capacity:
        sim.rad[e, n] = radiation_from(sim, c, step_key)
        sim.counts[e, N_RAD] = n + 1
    else:
        sim.counts[e, N_DROP_RAD] += 1


@ti.func
def convection_from(sim: ti.template(), c, step_key):
    """A new convection particle of burning cell c (its draws are keyed by the cell, not its pool slot)."""
    h = rng.key(step_key, c, rng.DOMAIN_EMISSION)
    i = c // sim.cols
    j = c % sim.cols
    # The reference's particle constructor takes whole metres: the emission point is truncated.
    x1 = ti.floor((i + rng.uniform(h)) * sim.cell_size)
    x2 = ti.floor((j + rng.uniform(rng.mix32(h))) * sim.cell_size)
    return ti.Vector([x1, x2, 0.0, 0.0, sim.conv_y_st], ti.f32)


@ti.func
def radiation_from(sim: ti.template(), c, step_key):
    """A new radiation particle of burning cell c (keyed by the cell, as convection_from)."""
    cls = sim.land[c]  # the mother class, never the burning state
    h = rng.key(step_key, c, rng.DOMAIN_EMISSION + 16)
    h2 = rng.mix32(h)
    sf = sim.cls_sf[cls]
    lr = sim.cls_lr[cls]
    sf_sample = ti.abs(sf[0] + sf[1] * sim.normals[rng.low16(h)])
    length = lr[0] + (lr[1] - lr[0]) * rng.uniform(h2)
    tau = 2703.0
    if sf_sample > 0.00925:
        tau = length / sf_sample
    i = c // sim.cols
    j = c % sim.cols
    o1 = (i + rng.uniform(rng.mix32(h2))) * sim.cell_size
    o2 = (j + rng.uniform(rng.mix32(h2 + ti.u32(1)))) * sim.cell_size
    return new_radiation(o1, o2, sim.rad_y_st, 1.0 - sim.dt / tau, cls)


@ti.func
def delete_particles_in(sim: ti.template(), e, c):
    """Water on cell c removes the particles over it (docs/model/fire.md §8); the others keep their order."""
    w = 0
    for i in range(sim.counts[e, N_CONV]):
        p = sim.conv[e, i]
        if sim.cell_of(p[P_X1], p[P_X2]) != c:
            sim.conv[e, w] = p
            w += 1
    sim.counts[e, N_CONV] = w
    w = 0
    for i in range(sim.counts[e, N_RAD]):
        p = sim.rad[e, i]
        x = radiation_position(p)
        if sim.cell_of(x[0], x[1]) != c:
            sim.rad[e, w] = p
            w += 1
    sim.counts[e, N_RAD] = w
