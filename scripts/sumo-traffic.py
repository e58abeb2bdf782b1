#!/usr/bin/env python3
"""Traffic that is not ours: an infotrack world plus N tracks of one car that Eclipse SUMO
drives through random waypoints among background traffic (randomTrips.py), its top speed
capped to what the field configs' drone can follow. SUMO routes the car, slows it for
turns, stops it at lights and behind other cars; infotrack only ever sees the tracks.

Two sources of streets:
  --osm EXTRACT --bbox W,S,E,N   an OpenStreetMap extract (.osm.pbf or .osm XML): the world
                                 is `infotrack world import` of it; SUMO's network is
                                 netconvert of the same box (cut with osmium for a .pbf);
                                 the tracks are SUMO FCD written with --fcd-output.geo.
  --netgenerate grid|spider|rand a network SUMO's netgenerate draws (seeded): written as
                                 OSM XML about --origin and imported the same way; the
                                 tracks are CSV t_s,lon_deg,lat_deg.

Writes into --out: NAME.geojson and NAME.toml (the world and a config that flies it, each
run i on track i mod N, cued where its track starts), tracks/, sumo/ (the network, routes,
logs) and traffic.json (what was made, with every seed and version).

Needs SUMO (PyPI eclipse-sumo and sumolib, pinned in tests/sumo/requirements.txt; the test
setup installs them into .deps/sumo) and, for a .pbf extract, Debian's osmium-tool.
"""

import argparse
import json
import math
import os
import random
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)


def ecef_of(lat_deg, lon_deg, h_m):
    """WGS84 geodetic -> Earth-centred, Earth-fixed, metres."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    n = WGS84_A / math.sqrt(1.0 - WGS84_E2 * math.sin(lat) ** 2)
    return (
        (n + h_m) * math.cos(lat) * math.cos(lon),
        (n + h_m) * math.cos(lat) * math.sin(lon),
        (n * (1.0 - WGS84_E2) + h_m) * math.sin(lat),
    )


def geodetic_of(x, y, z):
    """ECEF -> WGS84 (lat_deg, lon_deg, h_m), iterated to well under a millimetre."""
    lon = math.atan2(y, x)
    p = math.hypot(x, y)
    lat = math.atan2(z, p * (1.0 - WGS84_E2))
    for _ in range(10):
        n = WGS84_A / math.sqrt(1.0 - WGS84_E2 * math.sin(lat) ** 2)
        h = p / math.cos(lat) - n
        lat = math.atan2(z, p * (1.0 - WGS84_E2 * n / (n + h)))
    n = WGS84_A / math.sqrt(1.0 - WGS84_E2 * math.sin(lat) ** 2)
    return math.degrees(lat), math.degrees(lon), p / math.cos(lat) - n


def lonlat_of_enu(origin, east_m, north_m):
    """A point east/north of `origin` (lat_deg, lon_deg) on its ellipsoid height -> lon, lat."""
    lat0, lon0 = math.radians(origin[0]), math.radians(origin[1])
    x0, y0, z0 = ecef_of(origin[0], origin[1], 0.0)
    sl, cl, sp, cp = math.sin(lon0), math.cos(lon0), math.sin(lat0), math.cos(lat0)
    dx = -sl * east_m - sp * cl * north_m
    dy = cl * east_m - sp * sl * north_m
    dz = cp * north_m
    lat, lon, _ = geodetic_of(x0 + dx, y0 + dy, z0 + dz)
    return lon, lat


def run(cmd, log):
    """Runs a SUMO tool, its output appended to `log`; fails loudly with the tail."""
    with open(log, "a") as f:
        f.write("$ " + " ".join(cmd) + "\n")
        f.flush()
        done = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT)
    if done.returncode != 0:
        with open(log) as f:
            tail = f.read()[-3000:]
        sys.exit(f"sumo-traffic: {os.path.basename(cmd[0])} failed ({log}):\n{tail}")


def sumo_tool(name):
    """A SUMO binary of the installed eclipse-sumo (beside this Python), else on PATH."""
    here = os.path.join(os.path.dirname(sys.executable), name)
    found = here if os.path.exists(here) else shutil.which(name)
    if not found:
        sys.exit(f"sumo-traffic: {name} not found: install eclipse-sumo "
                 "(tests/sumo/requirements.txt) and run this with that Python")
    return found


def sumo_home():
    import sumo  # noqa: PLC0415 (only with SUMO installed)
    return sumo.SUMO_HOME


def net_from_osm(args, work, log):
    """netconvert of the box of an OSM extract (a .pbf cut to XML by osmium first)."""
    src = args.osm
    if src.endswith(".pbf"):
        if not shutil.which("osmium"):
            sys.exit("sumo-traffic: a .pbf extract needs osmium (Debian's osmium-tool)")
        src = os.path.join(work, "box.osm")
        run(["osmium", "extract", "--overwrite", "-b", args.bbox, "-s", "complete_ways",
             args.osm, "-o", src], log)
    net = os.path.join(work, "net.net.xml")
    run([sumo_tool("netconvert"), "--osm-files", src, "-o", net,
         "--keep-edges.by-vclass", "passenger", "--remove-edges.isolated",
         "--geometry.remove", "--junctions.join", "--tls.guess-signals", "--tls.discard-simple",
         "--ramps.guess", "--roundabouts.guess", "--keep-edges.components", "1",
         "--no-turnarounds.except-deadend", "--seed", str(args.seed)], log)
    return net


def net_from_netgenerate(args, work, log):
    """A network netgenerate draws with the seed (junctions 80-200 m apart, as in towns)."""
    net = os.path.join(work, "net.net.xml")
    side = max(2, round(math.sqrt(args.junctions)))
    kind = {
        "grid": ["--grid", "--grid.number", str(side), "--grid.length", "110",
                 "--rand.random-lanenumber", "false"],
        "spider": ["--spider", "--spider.arm-number", "7",
                   "--spider.circle-number", str(max(2, args.junctions // 7)),
                   "--spider.space-radius", "100"],
        "rand": ["--rand", "--rand.iterations", str(args.junctions * 2),
                 "--rand.min-distance", "80", "--rand.max-distance", "200",
                 "--rand.connectivity", "0.9"],
    }[args.netgenerate]
    run([sumo_tool("netgenerate"), *kind, "--default.lanenumber", "1",
         "--default.speed", "13.89", "--tls.guess", "--seed", str(args.seed),
         "--no-turnarounds.except-deadend", "-o", net], log)
    return net


def osm_of_net(net, origin, path):
    """The network's drivable edges as OSM XML (one oneway way per SUMO edge) about
    `origin`, for `infotrack world import`; returns the box W,S,E,N with a 60 m margin."""
    import sumolib  # noqa: PLC0415
    n = sumolib.net.readNet(net)
    root = ET.Element("osm", version="0.6", generator="infotrack sumo-traffic")
    ids, lon_lat = {}, []

    def node_of(xy):
        key = (round(xy[0], 2), round(xy[1], 2))
        if key not in ids:
            ids[key] = len(ids) + 1
            lon, lat = lonlat_of_enu(origin, *key)
            lon_lat.append((lon, lat))
            ET.SubElement(root, "node", id=str(ids[key]), version="1",
                          lat=f"{lat:.8f}", lon=f"{lon:.8f}")
        return ids[key]

    for k, e in enumerate(n.getEdges()):
        if not e.allows("passenger"):
            continue
        shape = e.getRawShape()
        points = [e.getFromNode().getCoord(), *shape[1:-1], e.getToNode().getCoord()]
        way = ET.SubElement(root, "way", id=str(k + 1), version="1")
        for p in points:
            ET.SubElement(way, "nd", ref=str(node_of(p)))
        for tag, value in [("highway", "residential"), ("oneway", "yes")]:
            ET.SubElement(way, "tag", k=tag, v=value)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
    lons, lats = [p[0] for p in lon_lat], [p[1] for p in lon_lat]
    m_lat = 60.0 / 111_000.0
    m_lon = m_lat / math.cos(math.radians(origin[0]))
    return f"{min(lons) - m_lon},{min(lats) - m_lat},{max(lons) + m_lon},{max(lats) + m_lat}"


def import_world(args, osm, bbox):
    """`infotrack world import` of the streets: NAME.geojson and NAME.toml in --out."""
    cmd = [args.infotrack, "world", "import", "--osm", osm, "--bbox", bbox,
           "--out", args.out, "--name", args.name]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"sumo-traffic: {' '.join(cmd)} failed:\n{done.stderr}")


def reachable(edge, step):
    """The edges reachable from `edge` along `step` (outgoing or incoming neighbours)."""
    seen, stack = {edge}, [edge]
    while stack:
        for e in step(stack.pop()):
            if e not in seen and e.allows("passenger"):
                seen.add(e)
                stack.append(e)
    return seen


def drivable_edges(net, rng):
    """Edges a passenger car may drive, over 15 m long, of a strongly connected part holding
    at least half of them (from anywhere in it to anywhere in it)."""
    cars = [e for e in net.getEdges() if e.allows("passenger")]
    for _ in range(50):
        hub = rng.choice(cars)
        part = reachable(hub, lambda e: e.getOutgoing().keys()) & reachable(
            hub, lambda e: e.getIncoming().keys())
        if len(part) * 2 >= len(cars):
            return [e for e in cars if e in part and e.getLength() > 15.0]
    sys.exit("sumo-traffic: no strongly connected part holds half the network's roads")


def waypoint_route(net, edges, rng, length_m):
    """A start, random waypoints and a destination (all in one strongly connected part, so
    each is reachable from the one before), the shortest paths between them together at
    least `length_m` long."""
    chain, total = [rng.choice(edges)], 0.0
    for _ in range(10_000):
        if total >= length_m:
            return chain
        nxt = rng.choice(edges)
        path, cost = net.getShortestPath(chain[-1], nxt, vClass="passenger")
        if path and cost > 150.0:
            chain.append(nxt)
            total += cost
    sys.exit("sumo-traffic: no route of the length asked for in 10,000 tries")


def background_trips(args, net, work, seed, log):
    """randomTrips.py's background traffic over the whole run."""
    trips = os.path.join(work, f"background-{seed}.trips.xml")
    # randomTrips validates through duarouter, whose routes go to ./routes.rou.xml unless
    # told otherwise; they belong in the work folder.
    routes = os.path.join(work, f"background-{seed}.rou.xml")
    tool = os.path.join(sumo_home(), "tools", "randomTrips.py")
    end = args.warmup + args.duration + 60
    run([sys.executable, tool, "-n", net, "-o", trips, "-r", routes, "-b", "0", "-e", str(end),
         "--insertion-density", str(args.traffic_density), "--fringe-factor", "5",
         "--min-distance", "300", "--seed", str(seed), "--validate",
         "--prefix", "bg", "--trip-attributes", 'departLane="best"'], log)
    return trips


def target_trip(args, chain, path):
    """The tracked car: capped top speed, SUMO routes it through the waypoints."""
    root = ET.Element("routes")
    ET.SubElement(root, "vType", id="tracked", vClass="passenger",
                  maxSpeed=f"{args.max_speed}", speedFactor="1.0", speedDev="0.1")
    via = " ".join(e.getID() for e in chain[1:-1])
    trip = ET.SubElement(root, "trip", id="target", type="tracked", depart=f"{args.warmup}",
                         departLane="best", departSpeed="0", **{"from": chain[0].getID(),
                                                               "to": chain[-1].getID()})
    if via:
        trip.set("via", via)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)


def drive(args, net, work, i, log):
    """Track i: SUMO drives the car among the background traffic; its FCD alone."""
    import sumolib  # noqa: PLC0415
    seed = args.seed * 1000 + i
    n = sumolib.net.readNet(net)
    rng = random.Random(seed)
    chain = waypoint_route(n, drivable_edges(n, rng), rng, args.max_speed * args.duration * 1.5)
    trip = os.path.join(work, f"target-{i:02d}.trips.xml")
    target_trip(args, chain, trip)
    bg = background_trips(args, net, work, seed, log)
    fcd = os.path.join(work, f"fcd-{i:02d}.xml")
    run([sumo_tool("sumo"), "-n", net, "-r", f"{trip},{bg}", "--seed", str(seed),
         "--begin", "0", "--end", str(args.warmup + args.duration + 5),
         "--fcd-output", fcd, *(["--fcd-output.geo"] if args.osm else []),
         "--device.fcd.explicit", "target",
         "--device.fcd.probability", "0", "--ignore-route-errors", "--time-to-teleport", "300",
         "--no-step-log", "--no-warnings", "--duration-log.disable"], log)
    return fcd


def fcd_samples(fcd):
    """(t_s, x, y) of the target in an FCD file: lon/lat with --fcd-output.geo, else the
    network's metres."""
    out = []
    for step in ET.parse(fcd).getroot().iter("timestep"):
        for v in step.iter("vehicle"):
            if v.get("id") == "target":
                out.append((float(step.get("time")), float(v.get("x")), float(v.get("y"))))
    return out


def keep_track(args, fcd, i):
    """The track as the user's file: the FCD itself for a real map, CSV lon/lat otherwise;
    None if SUMO never got the car moving for a minute."""
    samples = fcd_samples(fcd)
    if len(samples) < 60:
        return None
    os.makedirs(os.path.join(args.out, "tracks"), exist_ok=True)
    if args.osm:
        name = f"tracks/track-{i:02d}.xml"
        shutil.copyfile(fcd, os.path.join(args.out, name))
    else:
        name = f"tracks/track-{i:02d}.csv"
        with open(os.path.join(args.out, name), "w") as f:
            f.write("t_s,lon_deg,lat_deg\n")
            origin = tuple(float(v) for v in args.origin.split(","))
            for t, x, y in samples:
                lon, lat = lonlat_of_enu(origin, x, y)
                f.write(f"{t - samples[0][0]:.2f},{lon:.8f},{lat:.8f}\n")
    return name, samples[-1][0] - samples[0][0]


def fly_tracks(args, tracks):
    """The imported config flies the tracks, each run cued where its track starts: the
    GeoJSON's cue goes, `[acquisition]` keeps its radius and slowest speed."""
    gj_path = os.path.join(args.out, f"{args.name}.geojson")
    with open(gj_path) as f:
        gj = json.load(f)
    cues = [f for f in gj["features"] if f["properties"].get("infotrack") == "cue"]
    radius = cues[0]["properties"]["radius_m"] if cues else 150.0
    min_speed = cues[0]["properties"].get("min_speed_mps", 0.0) if cues else 0.0
    gj["features"] = [f for f in gj["features"] if f not in cues]
    with open(gj_path, "w") as f:
        json.dump(gj, f, indent=1)
        f.write("\n")
    toml_path = os.path.join(args.out, f"{args.name}.toml")
    with open(toml_path) as f:
        text = f.read()
    files = ", ".join(f'"{t}"' for t in tracks)
    text = text.replace("[target]\n", f"[target]\ntrajectory = [{files}]\n", 1)
    text += (f"\n# Each run is cued where its recorded track starts (cue_enu_m left out).\n"
             f"[acquisition]\ncue_radius_m = {radius}\nmin_speed_mps = {min_speed}\n")
    with open(toml_path, "w") as f:
        f.write(text)


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--osm", help="an OpenStreetMap extract, .osm.pbf or .osm")
    src.add_argument("--netgenerate", choices=["grid", "spider", "rand"])
    p.add_argument("--bbox", help="with --osm: lon_min,lat_min,lon_max,lat_max")
    p.add_argument("--junctions", type=int, default=100, help="with --netgenerate")
    p.add_argument("--origin", default="60.17,24.94",
                   help="with --netgenerate: lat,lon of the network's (0, 0)")
    p.add_argument("--out", required=True)
    p.add_argument("--name", default="traffic")
    p.add_argument("--tracks", type=int, default=4)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--duration", type=float, default=300.0, help="seconds each track lasts")
    p.add_argument("--warmup", type=float, default=120.0,
                   help="seconds of background traffic before the car departs")
    p.add_argument("--max-speed", type=float, default=12.0,
                   help="the car's top speed, m/s (the field configs' drone flies 15)")
    p.add_argument("--traffic-density", type=float, default=30.0,
                   help="background cars inserted per hour per km of road")
    p.add_argument("--infotrack", default="infotrack", help="the infotrack program")
    args = p.parse_args()
    if args.osm and not args.bbox:
        p.error("--osm needs --bbox")
    if args.tracks < 1 or args.duration <= 0 or args.max_speed <= 0:
        p.error("--tracks, --duration and --max-speed must be positive")
    return args


def main():
    args = parse_args()
    work = os.path.join(args.out, "sumo")
    os.makedirs(work, exist_ok=True)
    log = os.path.join(work, "sumo.log")
    open(log, "w").close()
    if args.osm:
        net = net_from_osm(args, work, log)
        import_world(args, args.osm, args.bbox)
    else:
        net = net_from_netgenerate(args, work, log)
        origin = tuple(float(v) for v in args.origin.split(","))
        osm = os.path.join(work, "net.osm")
        import_world(args, osm, osm_of_net(net, origin, osm))
    tracks, made = [], []
    for i in range(args.tracks):
        kept = keep_track(args, drive(args, net, work, i, log), i)
        if kept is None:
            print(f"sumo-traffic: track {i}: the car never drove a minute; left out",
                  file=sys.stderr)
            continue
        tracks.append(kept[0])
        made.append({"file": kept[0], "duration_s": round(kept[1], 1)})
    if not tracks:
        sys.exit("sumo-traffic: no track was driven")
    fly_tracks(args, tracks)
    summary = {"source": args.osm or f"netgenerate {args.netgenerate}", "seed": args.seed,
               "sumo": subprocess.run([sumo_tool("sumo"), "--version"], capture_output=True,
                                      text=True).stdout.splitlines()[0],
               "max_speed_mps": args.max_speed, "traffic_density_per_h_km": args.traffic_density,
               "tracks": made}
    with open(os.path.join(args.out, "traffic.json"), "w") as f:
        json.dump(summary, f, indent=1)
    print(f"{len(tracks)} track(s) in {args.out}; fly them with "
          f"infotrack sim --config {os.path.join(args.out, args.name + '.toml')}")


if __name__ == "__main__":
    main()
