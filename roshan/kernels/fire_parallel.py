"""One env's fire update spread over CPU threads, with the env-serial update's trajectory bit for bit.

The serial update (``FireSim.step_env``) walks four lists in order: convection particles, radiation particles,
exposed cells, burning cells. Here each list is cut into chunks. A parallel pass does each chunk's items in order
and writes what it keeps into the chunk's own stretch of a scratch buffer; a serial pass adds up the chunks'
counts (their running sums are where each chunk's output goes) and does, in list order, the little that depends
on order; a parallel pass copies every chunk's output to its place. Every list so ends in the serial order,
whatever the chunk boundaries or the thread count, and so do the particles' random streams (keyed by their
index) and every record.

What depends on order, and where it is done:

- A particle's visit to a cell without a record yet (the sparse layout hands out blocks in visit order) or to an
  ignitable cell not yet exposed (the exposed list grows in visit order): its chunk queues it and the serial
  pass replays the queue in order through the serial path's own ``visit``. Any other visit only stamps the
  cell with the update's number, which any order does alike.
- New fires join the burning list in exposed-list order: queued per chunk, appended serially.
- Emissions take the next pool slots in burning-list order, or are dropped once the pool is full: each chunk
  queues its emitting cells, the serial pass gives each chunk its first slot, and the chunks then make their
  particles in parallel (an emission's random draws are keyed by its cell, not its slot).

Flood drains stay serial (the list is short). Scratch is one env's worth, shared by the envs, which step one
after another (this path is for fewer envs than threads).
"""

import taichi as ti

from roshan.kernels import particles as pt
from roshan.kernels import rng
from roshan.kernels.fire_cells import record_of
from roshan.kernels.fire_records import (
    BURNED_OUT,
    C_FLAGS,
    C_STATE,
    C_VISIT,
    EMIT_CONV,
    EMIT_RAD,
    FLAG_EXPOSED,
    N_BURNED,
    N_BURNING,
    N_CONV,
    N_DROP_CONV,
    N_DROP_RAD,
    N_EXPOSED,
    N_LIT,
    N_RAD,
    N_STEP,
    T_EXPOSURE,
    T_IGN,
)

MAX_CHUNKS = 64  # per list
MIN_CHUNK = 256  # items: below this a chunk's work does not pay for its task
TASK = 512  # Taichi 1.7's CPU backend gives each task of a range-for 512 iterations: one chunk per task
CONV, RAD, EXPOSED, BURNING = range(4)  # the lists, in update order; rows of `plan`, blocks of `chunk` rows
PLAN_N, PLAN_SIZE, PLAN_COUNT = range(3)
# Per chunk: what it kept, what it queued, and per list: lit (EXPOSED); conv, rad emissions, burned out (BURNING)
K_KEPT, K_QUEUED, K_LIT, K_CONV, K_RAD, K_BURNED = 0, 1, 2, 2, 3, 4
# Per chunk, from the serial pass: where its kept items go, its first convection and radiation slot
F_OUT, F_CONV, F_RAD = range(3)


def scratch_bytes(conv_capacity: int, rad_capacity: int, list_capacity: int) -> int:
    """The scratch fields' bytes of a :class:`ChunkedStep` for these pool and list sizes (known before it is
    built: the memory estimate of :func:`roshan.kernels.fire_layout.fire_sizes` counts them)."""
    big = (pt.CONV_FIELDS * conv_capacity + pt.RAD_FIELDS * rad_capacity
           + max(conv_capacity + rad_capacity, list_capacity) + 2 * list_capacity)
    return 4 * (big + 4 * 3 + 4 * MAX_CHUNKS * (5 + 3) + 2)


@ti.data_oriented
class ChunkedStep:
    """The chunked update for a :class:`FireSim` (which builds it when ``fire.parallel`` picks ``chunks``)."""

    def __init__(self, sim, min_chunk: int = MIN_CHUNK):
        self.sim = sim
        self.min_chunk = min_chunk  # tests cut short lists into many chunks
        L = sim.list_capacity
        self.conv = ti.Vector.field(pt.CONV_FIELDS, ti.f32, sim.conv_capacity)  # moved particles, per chunk
        self.rad = ti.Vector.field(pt.RAD_FIELDS, ti.f32, sim.rad_capacity)
        self.queue = ti.field(ti.i32, max(sim.conv_capacity + sim.rad_capacity, L))  # visits, then emissions
        self.kept = ti.field(ti.i32, L)  # exposed cells that stay exposed
        self.fresh = ti.field(ti.i32, L)  # new fires, then burning cells that keep burning
        self.plan = ti.field(ti.i32, (4, 3))
        self.chunk = ti.field(ti.i32, (4 * MAX_CHUNKS, 5))
        self.first = ti.field(ti.i32, (4 * MAX_CHUNKS, 3))
        self.step_key = ti.field(ti.u32, ())
        self.update = ti.field(ti.i32, ())

    def memory_bytes(self) -> int:
        """Scratch bytes (one env's worth, whatever the number of envs)."""
        s = self.sim
        return scratch_bytes(s.conv_capacity, s.rad_capacity, s.list_capacity)

    def advance(self, n_steps: int) -> None:
        for _ in range(n_steps):
            for e in range(self.sim.num_envs):
                self._update(e)

    # ------------------------------------------------------------------------------------------ the update

    @ti.kernel
    def _update(self, e: ti.i32):
        ti.loop_config(serialize=True)  # a serial task: no thread-pool dispatch (~30 us here)
        for _ in range(1):  # serial: the update's number and key, the particle chunks
            t = self.sim.counts[e, N_STEP] + 1
            self.sim.counts[e, N_STEP] = t
            self.update[None] = t
            self.step_key[None] = rng.mix32(self.sim.env_key[e] ^ (ti.cast(t, ti.u32) * ti.u32(0x9E3779B9)))
            self._plan(CONV, self.sim.counts[e, N_CONV])
            self._plan(RAD, self.sim.counts[e, N_RAD])
        for v in range((self.plan[CONV, PLAN_COUNT] + self.plan[RAD, PLAN_COUNT]) * TASK):
            if v % TASK == 0:
                q = v // TASK
                if q < self.plan[CONV, PLAN_COUNT]:
                    self._move_convection(e, q)
                else:
                    self._move_radiation(e, q - self.plan[CONV, PLAN_COUNT])
        ti.loop_config(serialize=True)  # a serial task: no thread-pool dispatch (~30 us here)
        for _ in range(1):  # serial: particle counts, the queued visits in order, flood drains
            self._replay_visits(e)
            self.sim.drain_floods(e)
            self._plan(EXPOSED, self.sim.counts[e, N_EXPOSED])
        for v in range((self.plan[CONV, PLAN_COUNT] + self.plan[RAD, PLAN_COUNT]
                        + self.plan[EXPOSED, PLAN_COUNT]) * TASK):
            if v % TASK == 0:
                q = v // TASK
                nc, nr = self.plan[CONV, PLAN_COUNT], self.plan[RAD, PLAN_COUNT]
                if q < nc:
                    self._place_kept(e, CONV, q, self.conv, self.sim.conv)
                elif q < nc + nr:
                    self._place_kept(e, RAD, q - nc, self.rad, self.sim.rad)
                else:
                    self._expose(e, q - nc - nr)
        ti.loop_config(serialize=True)  # a serial task: no thread-pool dispatch (~30 us here)
        for _ in range(1):  # serial: the exposed list's length, new fires onto the burning list
            self._join_fires(e)
            self._plan(BURNING, self.sim.counts[e, N_BURNING])
        for v in range((self.plan[EXPOSED, PLAN_COUNT] + self.plan[BURNING, PLAN_COUNT]) * TASK):
            if v % TASK == 0:
                q = v // TASK
                if q < self.plan[EXPOSED, PLAN_COUNT]:
                    self._place_kept(e, EXPOSED, q, self.kept, self.sim.exposed)
                else:
                    self._burn(e, q - self.plan[EXPOSED, PLAN_COUNT])
        ti.loop_config(serialize=True)  # a serial task: no thread-pool dispatch (~30 us here)
        for _ in range(1):  # serial: the burning list's length, pool slots for the emissions
            self._share_slots(e)
        for v in range(self.plan[BURNING, PLAN_COUNT] * TASK):
            if v % TASK == 0:
                self._place_burning(e, v // TASK)

    # ------------------------------------------------------------------------------------------ chunks

    @ti.func
    def _plan(self, lst, n):
        """Cut a list of n items into at most MAX_CHUNKS chunks of at least MIN_CHUNK items."""
        size = ti.max(self.min_chunk, (n + MAX_CHUNKS - 1) // MAX_CHUNKS)
        self.plan[lst, PLAN_N] = n
        self.plan[lst, PLAN_SIZE] = size
        self.plan[lst, PLAN_COUNT] = (n + size - 1) // size

    @ti.func
    def _span(self, lst, q):
        lo = q * self.plan[lst, PLAN_SIZE]
        return lo, ti.min(lo + self.plan[lst, PLAN_SIZE], self.plan[lst, PLAN_N])

    @ti.func
    def _offsets(self, lst) -> ti.i32:
        """Each chunk's output offset (running sum of what the chunks kept); returns the total."""
        total = 0
        for q in range(self.plan[lst, PLAN_COUNT]):
            self.first[lst * MAX_CHUNKS + q, F_OUT] = total
            total += self.chunk[lst * MAX_CHUNKS + q, K_KEPT]
        return total

    # ------------------------------------------------------------------------------------------ particles

    @ti.func
    def _stamp(self, e, c, t) -> ti.i32:
        """A visit that needs no order: the cell has a record and is not an ignitable cell waiting to be
        exposed. Stamps it and returns 1; otherwise returns 0 (the visit is queued for the serial replay)."""
        r = record_of(self.sim, e, c)
        done = 0
        if r >= 0:
            self.sim.cells[e, r][C_VISIT] = t
            ignitable = self.sim.cls_ignitable[self.sim.cells[e, r][C_STATE]] != 0
            if not ignitable or (self.sim.cells[e, r][C_FLAGS] & FLAG_EXPOSED) != 0:
                done = 1
        return done

    @ti.func
    def _move_convection(self, e, q):
        t, step_key = self.update[None], self.step_key[None]
        lo, hi = self._span(CONV, q)
        wind = self.sim.wind[e]
        w = 0
        queued = 0
        for i in range(lo, hi):
            h = rng.key(step_key, i, rng.DOMAIN_CONVECTION)
            p = pt.advect_convection(self.sim.conv[e, i], wind, self.sim.normals[rng.low16(h)],
                                     self.sim.normals[rng.high16(h)], self.sim.conv_decay, self.sim.conv_f1dt,
                                     self.sim.conv_f2, self.sim.conv_fldt)
            c = self.sim.cell_of(p[pt.P_X1], p[pt.P_X2])
            if c >= 0 and p[pt.P_Y] >= self.sim.conv_y_lim:
                self.conv[lo + w] = p
                w += 1
                if self._stamp(e, c, t) == 0:
                    self.queue[lo + queued] = c
                    queued += 1
        self.chunk[CONV * MAX_CHUNKS + q, K_KEPT] = w
        self.chunk[CONV * MAX_CHUNKS + q, K_QUEUED] = queued

    @ti.func
    def _move_radiation(self, e, q):
        t, step_key = self.update[None], self.step_key[None]
        lo, hi = self._span(RAD, q)
        base = self.plan[CONV, PLAN_N]  # the queue holds the convection chunks' visits first
        w = 0
        queued = 0
        for i in range(lo, hi):
            h = rng.key(step_key, i, rng.DOMAIN_RADIATION)
            p = self.sim.rad[e, i]
            sf = self.sim.cls_sf[ti.cast(p[pt.R_CLS], ti.i32)]
            p = pt.advect_radiation(p, self.sim.unit[rng.low16(h)], self.sim.normals[rng.high16(h)],
                                    sf[0] * self.sim.dt, sf[1] * self.sim.sqrt_dt)
            x = pt.radiation_position(p)
            c = self.sim.cell_of(x[0], x[1])
            if c >= 0 and p[pt.R_Y] >= self.sim.rad_y_lim:
                self.rad[lo + w] = p
                w += 1
                if self._stamp(e, c, t) == 0:
                    self.queue[base + lo + queued] = c
                    queued += 1
        self.chunk[RAD * MAX_CHUNKS + q, K_KEPT] = w
        self.chunk[RAD * MAX_CHUNKS + q, K_QUEUED] = queued

    @ti.func
    def _replay_visits(self, e):
        t = self.update[None]
        self.sim.counts[e, N_CONV] = self._offsets(CONV)
        self.sim.counts[e, N_RAD] = self._offsets(RAD)
        for q in range(self.plan[CONV, PLAN_COUNT]):
            lo = q * self.plan[CONV, PLAN_SIZE]
            for k in range(self.chunk[CONV * MAX_CHUNKS + q, K_QUEUED]):
                self.sim.visit(e, self.queue[lo + k], t)
        base = self.plan[CONV, PLAN_N]
        for q in range(self.plan[RAD, PLAN_COUNT]):
            lo = base + q * self.plan[RAD, PLAN_SIZE]
            for k in range(self.chunk[RAD * MAX_CHUNKS + q, K_QUEUED]):
                self.sim.visit(e, self.queue[lo + k], t)

    @ti.func
    def _place_kept(self, e, lst: ti.template(), q, scratch: ti.template(), dest: ti.template()):
        """Chunk q's kept entries of list ``lst``, from their scratch span to their place in the env's list (the
        offsets give each chunk its first slot, so the kept entries stay in list order)."""
        lo = q * self.plan[lst, PLAN_SIZE]
        out = self.first[lst * MAX_CHUNKS + q, F_OUT]
        for k in range(self.chunk[lst * MAX_CHUNKS + q, K_KEPT]):
            dest[e, out + k] = scratch[lo + k]

    # ------------------------------------------------------------------------------------------ cells

    @ti.func
    def _expose(self, e, q):
        """FireSim._expose_and_ignite over one chunk of the exposed list (its cells are distinct)."""
        t = self.update[None]
        lo, hi = self._span(EXPOSED, q)
        w = 0
        lit = 0
        new = 0
        for k in range(lo, hi):
            c = self.sim.exposed[e, k]
            r = record_of(self.sim, e, c)
            flags = self.sim.cells[e, r][C_FLAGS]
            if self.sim.cells[e, r][C_VISIT] != t:
                self.sim.cells[e, r][C_FLAGS] = flags & ~FLAG_EXPOSED
            else:
                exposure = self.sim.timers[e, r][T_EXPOSURE] + ti.f64(self.sim.dt)
                self.sim.timers[e, r][T_EXPOSURE] = exposure
                if exposure >= self.sim.timers[e, r][T_IGN]:
                    self.sim.cells[e, r][C_FLAGS] = flags & ~FLAG_EXPOSED
                    lit += self.sim.light(e, r, c)
                    self.fresh[lo + new] = c
                    new += 1
                else:
                    self.kept[lo + w] = c
                    w += 1
        row = EXPOSED * MAX_CHUNKS + q
        self.chunk[row, K_KEPT] = w
        self.chunk[row, K_QUEUED] = new
        self.chunk[row, K_LIT] = lit

    @ti.func
    def _join_fires(self, e):
        self.sim.counts[e, N_EXPOSED] = self._offsets(EXPOSED)
        n = self.sim.counts[e, N_BURNING]
        for q in range(self.plan[EXPOSED, PLAN_COUNT]):
            row = EXPOSED * MAX_CHUNKS + q
            lo = q * self.plan[EXPOSED, PLAN_SIZE]
            for k in range(self.chunk[row, K_QUEUED]):
                self.sim.burning[e, n] = self.fresh[lo + k]
                n += 1
            self.sim.counts[e, N_LIT] += self.chunk[row, K_LIT]
        self.sim.counts[e, N_BURNING] = n

    @ti.func
    def _burn(self, e, q):
        """FireSim._burn over one chunk of the burning list; emitting cells are queued with their bits."""
        lo, hi = self._span(BURNING, q)
        w = 0
        queued = 0
        conv = 0
        rad = 0
        burned = 0
        for k in range(lo, hi):
            c = self.sim.burning[e, k]
            emits = self.sim.burn_tick(e, record_of(self.sim, e, c))
            if (emits & (EMIT_CONV | EMIT_RAD)) != 0:
                self.queue[lo + queued] = (c << 2) | (emits & (EMIT_CONV | EMIT_RAD))
                queued += 1
                conv += emits & EMIT_CONV
                rad += (emits & EMIT_RAD) >> 1
            if (emits & BURNED_OUT) != 0:
                burned += 1
            else:
                self.fresh[lo + w] = c
                w += 1
        row = BURNING * MAX_CHUNKS + q
        self.chunk[row, K_KEPT] = w
        self.chunk[row, K_QUEUED] = queued
        self.chunk[row, K_CONV] = conv
        self.chunk[row, K_RAD] = rad
        self.chunk[row, K_BURNED] = burned

    @ti.func
    def _share_slots(self, e):
        """The burning list's length, and each chunk's first pool slots; emissions past a full pool are dropped
        and counted, as the serial path drops every emission once its pool is full."""
        self.sim.counts[e, N_BURNING] = self._offsets(BURNING)
        conv = self.sim.counts[e, N_CONV]
        rad = self.sim.counts[e, N_RAD]
        for q in range(self.plan[BURNING, PLAN_COUNT]):
            row = BURNING * MAX_CHUNKS + q
            self.first[row, F_CONV] = conv
            self.first[row, F_RAD] = rad
            conv += self.chunk[row, K_CONV]
            rad += self.chunk[row, K_RAD]
            self.sim.counts[e, N_BURNED] += self.chunk[row, K_BURNED]
        self.sim.counts[e, N_DROP_CONV] += ti.max(0, conv - self.sim.conv_capacity)
        self.sim.counts[e, N_DROP_RAD] += ti.max(0, rad - self.sim.rad_capacity)
        self.sim.counts[e, N_CONV] = ti.min(conv, self.sim.conv_capacity)
        self.sim.counts[e, N_RAD] = ti.min(rad, self.sim.rad_capacity)

    @ti.func
    def _place_burning(self, e, q):
        step_key = self.step_key[None]
        row = BURNING * MAX_CHUNKS + q
        lo = q * self.plan[BURNING, PLAN_SIZE]
        self._place_kept(e, BURNING, q, self.fresh, self.sim.burning)
        conv = self.first[row, F_CONV]
        rad = self.first[row, F_RAD]
        for k in range(self.chunk[row, K_QUEUED]):
            item = self.queue[lo + k]
            c = item >> 2
            if (item & EMIT_CONV) != 0:
                if conv < self.sim.conv_capacity:
                    self.sim.conv[e, conv] = pt.convection_from(self.sim, c, step_key)
                conv += 1
            if (item & EMIT_RAD) != 0:
                if rad < self.sim.rad_capacity:
                    self.sim.rad[e, rad] = pt.radiation_from(self.sim, c, step_key)
                rad += 1
