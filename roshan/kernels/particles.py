"""Convection and radiation particle updates (docs/model/fire.md §7) as pure ``ti.func``s on particle records.

Records are f32 vectors so a particle is one contiguous load and store in the serial per-env pass.
"""


import taichi as ti

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
