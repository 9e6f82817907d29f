"""Initial fire generator (docs/model/fire.md §11): cluster, scattered, ring and random patterns.

The newest code re-seeds a cluster whose growth got trapped until it has its share of the fires, so a 35 %
setting lights 35 % of the cells; the thesis-era code (``ignition.reseed: false``) does not, so there the
percentage is a maximum (each cluster is a self-avoiding random walk that stops when trapped).

Runs serially inside one env of the reset kernel, drawing from that env's counter-based stream, so the
layout depends only on (seed, env, episode). Functions take the simulator as ``ti.template()`` and use its
fields: ``exposed`` serves as the BFS queue (``list_capacity`` long), ``cand`` for neighbours, and each cell's
generator mark (``mark_of`` / ``set_mark``) holds the used / visited flags.
"""


import taichi as ti

from roshan.kernels import rng

PATTERNS = ("cluster", "scattered", "ring", "random")
CLUSTER, SCATTERED, RING, RANDOM = range(4)
USED = 1  # taken by some cluster (shared between clusters)
MAX_START_TRIES = 100_000
MAX_RESEED_FAILURES = 200
RESEED_FRONTIER_TRIES = 30
RESEED_RANDOM_TRIES = 20
MAX_SCATTER_TRIES = 1_000_000
MAX_RING_FILL_TRIES = 100_000


@ti.func
def light_initial_fires(sim: ti.template(), e):
    # A fixed pattern is chosen at compile time: Taichi builds only that generator's code, which halves the reset
    # kernel's compile time at every start. ``random`` draws one per episode (even when no fire is lit).
    if ti.static(sim.pattern == RANDOM):
        p = rng.uniform_int(_draw(sim, e), 3)
        if sim.num_fires > 0:
            if p == CLUSTER:
                _light_clusters(sim, e)
            elif p == SCATTERED:
                _light_scattered(sim, e, sim.num_fires)
            else:
                _light_rings(sim, e)
    elif sim.num_fires > 0:
        if ti.static(sim.pattern == CLUSTER):
            _light_clusters(sim, e)
        elif ti.static(sim.pattern == SCATTERED):
            _light_scattered(sim, e, sim.num_fires)
        else:
            _light_rings(sim, e)


@ti.func
def _draw(sim: ti.template(), e) -> ti.u32:
    k = sim.gen_ctr[e]
    sim.gen_ctr[e] = k + 1
    return rng.key(sim.env_key[e], rng.DOMAIN_IGNITION, k)


@ti.func
def _uniform(sim: ti.template(), e) -> ti.f32:
    return rng.uniform(_draw(sim, e))


@ti.func
def _random_cell(sim: ti.template(), e) -> ti.i32:
    return rng.uniform_int(_draw(sim, e), sim.num_cells)


@ti.func
def _fresh(sim: ti.template(), e, c, tag) -> ti.i32:
    """Not visited by this cluster, not used by any, and ignitable: a candidate to grow into."""
    m = sim.mark_of(e, c)
    return ti.cast((m & USED) == 0 and (m >> 1) != tag and sim.can_ignite(e, c) != 0, ti.i32)


@ti.func
def _cluster_size(n_fires, n_clusters, c):
    size = n_fires // n_clusters
    if c == n_clusters - 1:
        size += n_fires % n_clusters
    return size


@ti.func
def _light_clusters(sim: ti.template(), e):
    n_clusters = ti.max(1, ti.min(sim.num_clusters, sim.num_fires))
    for c in range(n_clusters):
        start = -1
        for _ in range(MAX_START_TRIES):
            cell = _random_cell(sim, e)
            if (sim.mark_of(e, cell) & USED) == 0 and sim.can_ignite(e, cell) != 0:
                start = cell
                break
        if start >= 0:
            _grow_cluster(sim, e, start, _cluster_size(sim.num_fires, n_clusters, c), c + 1)


@ti.func
def _push(sim: ti.template(), e, tail, c, tag, used):
    """Queue c, marked visited by this cluster (and used); not if the queue or the sparse pool is full."""
    n = tail
    if n < sim.list_capacity:
        if sim.set_mark(e, c, (sim.mark_of(e, c) & USED) | used | (tag << 1)) != 0:
            sim.exposed[e, n] = c
            n += 1
    return n


@ti.func
def _gather_neighbours(sim: ti.template(), e, c, tag, only_fresh) -> ti.i32:
    """Write the in-grid Moore neighbours of c (only the fresh ones if ``only_fresh``) into sim.cand[e, :]."""
    n = 0
    i = c // sim.cols
    j = c % sim.cols
    # A loop, not a static unroll: each neighbour's freshness test inlines the sparse record lookup, and eight
    # copies of it (times the two callers) made the reset kernel the suite's slowest compile. Row-major order, the
    # centre skipped, as before.
    for k in range(9):
        ni = i + k // 3 - 1
        nj = j + k % 3 - 1
        if k != 4 and 0 <= ni < sim.rows and 0 <= nj < sim.cols:
            nc = ni * sim.cols + nj
            if only_fresh == 0 or _fresh(sim, e, nc, tag) != 0:
                sim.cand[e, n] = nc
                n += 1
    return n


@ti.func
def _shuffle_candidates(sim: ti.template(), e, n):
    for k in range(n - 1):  # Fisher-Yates
        r = k + rng.uniform_int(_draw(sim, e), n - k)
        tmp = sim.cand[e, k]
        sim.cand[e, k] = sim.cand[e, r]
        sim.cand[e, r] = tmp


@ti.func
def _grow_cluster(sim: ti.template(), e, start, size, tag):
    """Breadth-first growth with probabilistic spread, one-cell tendrils and (newest code) re-seeding."""
    head = 0
    tail = _push(sim, e, 0, start, tag, 0)
    first_lit = sim.burning_count(e)  # this cluster's fires are burning[first_lit : first_lit + ignited]
    ignited = 0
    failures = 0
    while head < tail and ignited < size:
        cell = sim.exposed[e, head]
        head += 1
        if sim.can_ignite(e, cell) != 0:
            sim.ignite(e, cell)
            ignited += 1
        sim.set_mark(e, cell, sim.mark_of(e, cell) | USED)
        n = _gather_neighbours(sim, e, cell, tag, 1)
        if head == tail and ignited < size and n > 0:
            # Keep a one-cell tendril growing: a random fresh neighbour (= shuffle, take the first).
            tail = _push(sim, e, tail, sim.cand[e, rng.uniform_int(_draw(sim, e), n)], tag, USED)
        else:
            for k in range(n):
                r = _uniform(sim, e)
                p = sim.spread_prob + (_uniform(sim, e) - 0.5) * sim.spread_noise
                if r < p:
                    tail = _push(sim, e, tail, sim.cand[e, k], tag, USED)
            if ti.static(sim.reseed) and head == tail and ignited < size and failures < MAX_RESEED_FAILURES:
                pushed = 0
                if ignited > 0:
                    res = _reseed_from_frontier(sim, e, tail, tag, first_lit, ignited)
                    pushed = res[0]
                    tail = res[1]
                if pushed == 0:
                    failures += 1
                    tail = _reseed_at_random(sim, e, tail, tag)


@ti.func
def _reseed_from_frontier(sim: ti.template(), e, tail, tag, first_lit, ignited):
    pushed = 0
    for _ in range(RESEED_FRONTIER_TRIES):
        src = sim.burning_cell(e, first_lit + rng.uniform_int(_draw(sim, e), ignited))
        n = _gather_neighbours(sim, e, src, tag, 0)
        _shuffle_candidates(sim, e, n)
        for k in range(n):
            nc = sim.cand[e, k]
            if pushed == 0 and _fresh(sim, e, nc, tag) != 0:
                tail = _push(sim, e, tail, nc, tag, 0)  # marked visited but not used, as the reference does
                pushed = 1
        if pushed != 0:
            break
    return ti.Vector([pushed, tail], ti.i32)


@ti.func
def _reseed_at_random(sim: ti.template(), e, tail, tag):
    for _ in range(RESEED_RANDOM_TRIES):
        cell = _random_cell(sim, e)
        if _fresh(sim, e, cell, tag) != 0:
            tail = _push(sim, e, tail, cell, tag, 0)
            break
    return tail


@ti.func
def _light_scattered(sim: ti.template(), e, n_fires):
    """Uniform random single cells; lights nothing (and flags the env) if too few ignitable cells remain."""
    available = 0
    for c in range(sim.num_cells):
        available += sim.can_ignite(e, c)
    if available < n_fires:
        sim.report_ignition_short(e, n_fires - available)
    else:
        _scatter(sim, e, 0, n_fires, MAX_SCATTER_TRIES)


@ti.func
def _scatter(sim: ti.template(), e, lit, n_fires, tries: ti.template()):
    """Light random ignitable cells until ``n_fires`` are lit (``lit`` already are) or ``tries`` draws are spent."""
    n = lit
    for _ in range(tries):
        if n >= n_fires:
            break
        c = _random_cell(sim, e)
        if sim.can_ignite(e, c) != 0:
            sim.ignite(e, c)
            n += 1


@ti.func
def _light_rings(sim: ti.template(), e):
    n_rings = ti.max(1, ti.min(sim.num_clusters, sim.num_fires))
    for r in range(n_rings):
        _light_ring(sim, e, _cluster_size(sim.num_fires, n_rings, r))


@ti.func
def _light_ring(sim: ti.template(), e, n_fires):
    """An annulus of ~n_fires cells around a random centre; a shortfall is filled with scattered fires."""
    centre = _random_cell(sim, e)
    ci = centre // sim.cols
    cj = centre % sim.cols
    radius = ti.max(2.0, ti.sqrt(n_fires / 3.141592653589793))
    thickness = ti.max(1.0, n_fires / (6.283185307179586 * radius))
    r_in = ti.max(0.0, radius - thickness / 2.0)
    r_out = radius + thickness / 2.0
    reach = ti.cast(ti.ceil(r_out), ti.i32)
    n = 0
    for di in range(-reach, reach + 1):
        for dj in range(-reach, reach + 1):
            i = ci + di
            j = cj + dj
            d = ti.sqrt(ti.cast(di * di + dj * dj, ti.f32))
            if 0 <= i < sim.rows and 0 <= j < sim.cols and r_in <= d <= r_out:
                c = i * sim.cols + j
                if sim.can_ignite(e, c) != 0 and n < sim.list_capacity:
                    sim.exposed[e, n] = c
                    n += 1
    lit = 0
    for k in range(n):  # partial Fisher-Yates over the annulus cells: the first n_fires of a shuffle
        if lit < n_fires:
            pick = k + rng.uniform_int(_draw(sim, e), n - k)
            c = sim.exposed[e, pick]
            sim.exposed[e, pick] = sim.exposed[e, k]
            sim.ignite(e, c)
            lit += 1
    _scatter(sim, e, lit, n_fires, MAX_RING_FILL_TRIES)
