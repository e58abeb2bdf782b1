#!/usr/bin/env python3
"""Write a field-scale world drawn at random, for measuring infotrack on worlds nobody tuned to.

    python3 scripts/random-world.py SEED [TWO_WAY_SHARE] [--orientation robbins|random] > world.toml
    infotrack sim --config world.toml --runs 10 --guidance eer --motion cv

The field-scale targets are measured on a field world we have not seen, written in the config
schema plus `[acquisition]`. The hand-made stand-ins (config/field-*.toml) were each written
to hold one difficulty; this draws the world itself from a seed so that a batch over seeds is
a sample of worlds, not a choice: a jittered grid of junctions 350-550 m apart, a fifth of
the streets dropped (the graph kept connected), each street two-way with probability
TWO_WAY_SHARE (default 0.5; a two-way street lets the car turn back at its junctions, since
the schema's turn probabilities belong to the node), the one-way streets oriented so that
every junction reaches every other (`robbins`, the default: a depth-first orientation, a
street that is the only link between two parts two-way; `random`: each drawn at random, then
made two-way until every junction reaches every other, the first draw of BENCHMARKS.md),
turn probabilities drawn per junction, a car at 10-15 m/s, a drone at 45-60 m with a 1280 or
1920 px camera, 1-1.5 m tag, one covered junction and one tree line along a street, the
operator's cue within 50 m of the car's start. The filter and guidance sections are the
stand-ins' (no optional key a world writer would not know, no model). Python's own `random`
only, so the same seed writes the same world on any machine.
"""

import argparse
import math
import random


def strongly_connected(n, directed):
    """Whether every node reaches every other along `directed` (a set of (a, b))."""
    def reach(adj):
        seen, stack = {0}, [0]
        while stack:
            a = stack.pop()
            for b in adj[a]:
                if b not in seen:
                    seen.add(b)
                    stack.append(b)
        return len(seen) == n

    fwd = {i: [] for i in range(n)}
    back = {i: [] for i in range(n)}
    for a, b in directed:
        fwd[a].append(b)
        back[b].append(a)
    return reach(fwd) and reach(back)


def robbins_orientation(n, streets, rng):
    """One-way streets that keep every junction reachable from every other where the street
    graph allows it (Robbins' theorem): a depth-first search from a random junction, tree
    streets away from the root, the others back toward the ancestor they close a loop with."""
    adj = {i: [] for i in range(n)}
    for a, b in streets:
        adj[a].append(b)
        adj[b].append(a)
    for v in adj.values():
        rng.shuffle(v)
    order, directed, done = {}, set(), set()

    def dfs(v):
        order[v] = len(order)
        for u in adj[v]:
            key = frozenset((u, v))
            if key in done:
                continue
            done.add(key)
            # First met from v: a tree street (u new) or a loop closed back to an ancestor.
            directed.add((v, u))
            if u not in order:
                dfs(u)

    dfs(rng.randrange(n))
    return directed


def draw_graph(rng, two_way_share, orientation):
    """Junctions (id, x, y) and directed streets (a, b, p)."""
    rows, cols = rng.choice([(2, 3), (3, 3), (2, 4), (3, 4)])
    spacing = rng.uniform(350.0, 550.0)
    jitter = 0.18 * spacing
    nodes = []
    for r in range(rows):
        for c in range(cols):
            nodes.append((r * cols + c, c * spacing + rng.uniform(-jitter, jitter),
                          r * spacing + rng.uniform(-jitter, jitter)))
    nodes[0] = (0, 0.0, 0.0)
    streets = []
    for r in range(rows):
        for c in range(cols):
            i = r * cols + c
            if c + 1 < cols:
                streets.append((i, i + 1))
            if r + 1 < rows:
                streets.append((i, i + cols))
    rng.shuffle(streets)
    n = len(nodes)
    # Drop about a fifth of the streets, keeping the undirected graph connected.
    kept = list(streets)
    for s in streets[: len(streets) // 5]:
        trial = [t for t in kept if t != s]
        if strongly_connected(n, set(trial) | {(b, a) for a, b in trial}):
            kept = trial
    if orientation == "random":
        return nodes, turn_probabilities(n, randomly_oriented(n, kept, two_way_share, rng), rng)
    directed = robbins_orientation(n, kept, rng)
    for a, b in kept:
        if rng.random() < two_way_share:
            directed |= {(a, b), (b, a)}
    # A bridge (a street whose loss splits the graph) has no one-way orientation: two-way.
    for a, b in kept:
        rest = [t for t in kept if t != (a, b)]
        if not strongly_connected(n, set(rest) | {(y, x) for x, y in rest}):
            directed |= {(a, b), (b, a)}
    assert strongly_connected(n, directed)
    return nodes, turn_probabilities(n, directed, rng)


def randomly_oriented(n, streets, two_way_share, rng):
    """The first draw (worlds 1-8 of BENCHMARKS.md): each street two-way with
    probability `two_way_share`, else one way at random; then one-way streets made two-way,
    in random order, until every junction reaches every other (so even a share of 0 leaves
    many streets two-way)."""
    directed = set()
    one_way = []
    for a, b in streets:
        if rng.random() < two_way_share:
            directed |= {(a, b), (b, a)}
        else:
            d = (a, b) if rng.random() < 0.5 else (b, a)
            directed.add(d)
            one_way.append(d)
    rng.shuffle(one_way)
    while not strongly_connected(n, directed):
        a, b = one_way.pop()
        directed.add((b, a))
    return directed


def turn_probabilities(n, directed, rng):
    """Directed streets (a, b, p): each junction's ways on with probabilities drawn for it."""
    edges = []
    for a in range(n):
        outs = sorted(b for (x, b) in directed if x == a)
        weights = [rng.gammavariate(2.0, 1.0) for _ in outs]
        total = sum(weights)
        ps = [round(w / total, 2) for w in weights]
        ps = [max(p, 0.05) for p in ps]
        ps[-1] = round(1.0 - sum(ps[:-1]), 2)
        if ps[-1] <= 0.0:
            ps = [round(1.0 / len(outs), 2)] * len(outs)
            ps[-1] = round(1.0 - sum(ps[:-1]), 2)
        edges += [(a, b, p) for b, p in zip(outs, ps)]
    return edges


def rect(cx, cy, hx, hy):
    return [[round(cx - hx, 1), round(cy - hy, 1)], [round(cx + hx, 1), round(cy - hy, 1)],
            [round(cx + hx, 1), round(cy + hy, 1)], [round(cx - hx, 1), round(cy + hy, 1)]]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("seed", type=int)
    parser.add_argument("two_way_share", type=float, nargs="?", default=0.5)
    parser.add_argument("--orientation", choices=["robbins", "random"], default="robbins",
                        help="how one-way streets get their direction (default robbins; "
                        "random: the first draw, worlds 1-8 of BENCHMARKS.md)")
    args = parser.parse_args()
    if not 0.0 <= args.two_way_share <= 1.0:
        parser.error(f"two_way_share must lie in [0, 1], got {args.two_way_share}")
    seed, two_way_share = args.seed, args.two_way_share
    rng = random.Random(seed)
    nodes, edges = draw_graph(rng, two_way_share, args.orientation)
    xs = [x for _, x, _ in nodes]
    ys = [y for _, _, y in nodes]
    x0, x1 = min(xs) - 200.0, max(xs) + 200.0
    y0, y1 = min(ys) - 200.0, max(ys) + 200.0
    cruise = round(rng.uniform(10.0, 15.0), 1)
    altitude = rng.choice([45.0, 50.0, 55.0, 60.0])
    fov_x = round(rng.uniform(1.0, 1.3), 2)
    fov_y = round(fov_x * rng.uniform(0.56, 0.62), 2)
    # A covered junction (not the start) and a tree line along the middle of a street.
    cj = rng.choice(nodes[1:])
    deck = rect(cj[1], cj[2], 50.0, 50.0)
    ta, tb, _ = rng.choice([e for e in edges if e[0] != 0 and e[1] != 0])
    (ax, ay), (bx, by) = (nodes[ta][1:], nodes[tb][1:])
    mx, my = (ax + bx) / 2, (ay + by) / 2
    along_x = abs(bx - ax) > abs(by - ay)
    trees = rect(mx, my, 100.0, 30.0) if along_x else rect(mx, my, 30.0, 100.0)
    view_x = 2 * altitude * math.tan(fov_x / 2)
    legs = []
    x = x0 + view_x / 2
    while x < x1:
        legs.append(round(x, 1))
        x += view_x
    cue_ang = rng.uniform(0, 2 * math.pi)
    cue_r = rng.uniform(0.0, 50.0)
    out = []
    w = out.append
    w(f"# Drawn by scripts/random-world.py {seed} {two_way_share} --orientation {args.orientation}:"
      " a world nobody tuned to.")
    w(f'name = "random-{seed}"')
    w(f"seed = {seed}")
    w("")
    w("[workspace_enu]")
    w(f"x_min_m = {x0:.1f}\nx_max_m = {x1:.1f}\ny_min_m = {y0:.1f}\ny_max_m = {y1:.1f}")
    w("")
    w("[road]\nstart_node = 0\nnodes = [")
    for i, x, y in nodes:
        w(f"  {{ id = {i}, x_m = {x:.1f}, y_m = {y:.1f} }},")
    w("]\nedges = [")
    for a, b, p in edges:
        w(f"  {{ from = {a}, to = {b}, p = {p} }},")
    w("]")
    w("")
    w(f'[[occlusions]]\nname = "deck over junction {cj[0]}"\nvertices_enu_m = {deck}')
    w("")
    w(f'[[occlusions]]\nname = "trees along {ta}-{tb}"\nvertices_enu_m = {trees}')
    w("")
    w("[target]")
    w(f"cruise_speed_mps = {cruise}\nmax_speed_mps = {cruise + 2.0:.1f}")
    w(f"max_yaw_rate_radps = {rng.uniform(0.5, 0.8):.2f}\nturn_in_place_above_rad = 1.2")
    w("heading_gain_per_s = 1.5\ngoal_switch_radius_m = 8.0")
    w("")
    w("[agent]")
    w(f"altitude_m = {altitude}")
    w(f"start_enu_m = [{rng.uniform(-60, -20):.1f}, {rng.uniform(-60, -20):.1f}]")
    w(f"gain_per_s = 0.5\nspeed_limit_mps = {cruise + rng.uniform(4.0, 6.0):.1f}")
    w("accel_limit_mps2 = 4.0\ndead_zone_m = 2.0")
    w("")
    w(f"[camera]\nfov_x_rad = {fov_x}\nfov_y_rad = {fov_y}")
    w("")
    w("[measurement]\nnoise_cov_m2 = [[1.5, 0.0], [0.0, 1.5]]")
    w("")
    w("[timing]\nfilter_hz = 3.0\nguidance_hz = 1.0\nphysics_hz = 30.0\nduration_s = 300.0")
    w("")
    w("[filter]\nparticles = 1000\nhistory_len = 10")
    w("process_noise_cov_m2 = [[1.5, 0.0], [0.0, 1.5]]")
    w("resample_threshold = 0.99\nreseed_threshold = 0.4\nroughening = 0.2")
    w("miss_probability = 1e-6\nmax_outside_fraction = 0.5")
    w("")
    w(f"[motion]\ncv_max_speed_mps = {cruise + 4.0:.1f}")
    w("")
    w("[kalman]\nprocess_noise_diag = [1.0, 1.0, 0.5, 0.5]")
    w("initial_cov_diag = [400.0, 400.0, 25.0, 25.0]")
    w("")
    w("[guidance]\nentropy_particles = 1000\nmeasurements_per_particle = 1\nhorizon_steps = 6")
    w("candidate_grid_side = 16\nentropy_kernel_cov_m2 = [[1.5, 0.0], [0.0, 1.5]]")
    w("")
    w(f"[guidance.lawn]\nlegs_x_m = {legs}\ny_min_m = {y0 + 40:.1f}\ny_max_m = {y1 - 40:.1f}")
    w("point_spacing_m = 5.0\ntrack_measurement_for_s = 0.34")
    w("")
    w("[acquisition]")
    w(f"cue_enu_m = [{cue_r * math.cos(cue_ang):.1f}, {cue_r * math.sin(cue_ang):.1f}]")
    w("cue_radius_m = 150.0")
    w("")
    w(f"[vision]\nimage_width_px = {rng.choice([1280, 1920])}")
    w(f"tag_size_m = {rng.choice([1.0, 1.2, 1.5])}")
    print("\n".join(out))


if __name__ == "__main__":
    main()
