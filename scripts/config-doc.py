#!/usr/bin/env python3
"""Writes docs/src/config.md, the reference of every config key, from the config structs.

Each key's description is its doc comment in the Rust source (which gives its unit and,
where it has one, its range), its value in the lab scenario is what `infotrack config`
prints for the embedded default (defaults filled in), and its upper bound, where
`crates/infotrack-config/src/bounds.rs` sets one, is added. `--check` compares with the file instead of
writing it (tests/config_doc.rs runs that, so the reference cannot drift from the code).

Usage: python3 scripts/config-doc.py [--check] [--bin target/release/infotrack]
"""
import argparse
import pathlib
import re
import subprocess
import sys
import tomllib

ROOT = pathlib.Path(__file__).resolve().parent.parent
# Where each config struct is defined.
SOURCES = [
    "crates/infotrack-config/src/lib.rs",
    "crates/infotrack-core/src/world/sections.rs",
    "crates/infotrack-core/src/tracker/sections.rs",
    "crates/infotrack-core/src/estimation/sections.rs",
    "crates/infotrack-core/src/motion/sections.rs",
    "crates/infotrack-core/src/guidance/sections.rs",
    "crates/infotrack-core/src/world/road.rs",
    "crates/infotrack-core/src/world/geometry.rs",
    "crates/infotrack-vision/src/detector.rs",
    "crates/infotrack-vision/src/projection.rs",
    "crates/infotrack-core/src/guidance/lawn.rs",
    "crates/infotrack-core/src/geodesy.rs",
]
SECTION_DOC = {
    "": "Top level",
}


def structs():
    """{struct name: [(field, type, doc)]} for every braced struct in SOURCES."""
    out = {}
    for rel in SOURCES:
        text = (ROOT / rel).read_text()
        for m in re.finditer(r"pub struct (\w+) \{(.*?)\n\}", text, re.S):
            fields, doc = [], []
            for line in m.group(2).splitlines():
                line = line.strip()
                if line.startswith("///"):
                    doc.append(line[3:].strip())
                elif line.startswith("#["):
                    continue
                else:
                    f = re.match(r"pub (\w+): (.+),$", line)
                    if f:
                        fields.append((f.group(1), f.group(2), " ".join(doc)))
                    doc = []
            out[m.group(1)] = fields
    return out


def bounds():
    """{key: 'at most N'} from the checks in crates/infotrack-config/src/bounds.rs."""
    text = (ROOT / "crates/infotrack-config/src/bounds.rs").read_text()
    consts = {
        m.group(1): float(m.group(2).replace("_", ""))
        for m in re.finditer(r"pub const (\w+): \w+ = ([0-9_.]+);", text)
    }

    def value(expr):
        expr = expr.strip()
        for name, v in consts.items():
            expr = re.sub(rf"\b{name}\b", repr(v), expr)
        v = eval(expr, {"__builtins__": {}})  # numbers and * only, from our own source
        return f"at most {v:g}"

    out = {}
    # One key: at_most("key", value, BOUND) or at_most_usize(...).
    for m in re.finditer(r'at_most(?:_usize)?\(\s*"([\w.]+)",\s*[^,]+,\s*([^)]+?),?\s*\)', text):
        out.setdefault(m.group(1), value(m.group(2)))
    # Several keys in a loop: for (k, v) in [("key", ...), ...] { at_most(k, v, BOUND)?; }
    for m in re.finditer(r"for \(k, v\) in \[(.*?)\] \{\s*at_most\(k, v, ([^)]+)\)", text, re.S):
        for key in re.findall(r'"([\w.]+)"', m.group(1)):
            out.setdefault(key, value(m.group(2)))
    out["timing.duration_s"] = (
        f"at most {consts['MAX_DURATION_S']:g}, and duration x physics_hz at most "
        f"{consts['MAX_TICKS']:g}"
    )
    return out


def inner_struct(ty, known):
    """The config struct a field's type holds, if any (Option<X>, Vec<X>, crate::a::X)."""
    for name in re.findall(r"\w+", ty):
        if name in known:
            return name
    return None


def value_text(v):
    if v is None:
        return "none"
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, list) and len(v) > 4:
        return f"{len(v)} entries"
    if isinstance(v, list) and v and isinstance(v[0], dict):
        return f"{len(v)} entries"
    text = str(v).replace("'", '"').replace("True", "true").replace("False", "false")
    # A list in a code span: Markdown would read "[a, b]" as a link's text.
    return f"`{text}`" if isinstance(v, list) else text


def rows(all_structs, name, prefix, values, limits, out):
    # A section's own keys first, then its sub-sections (as TOML writes them).
    fields = sorted(
        all_structs[name], key=lambda f: inner_struct(f[1], all_structs) is not None
    )
    for field, ty, doc in fields:
        key = f"{prefix}{field}"
        inner = inner_struct(ty, all_structs)
        v = values.get(field) if isinstance(values, dict) else None
        if inner and "Vec<" not in ty:
            out.append(("section", key, ty, doc))
            rows(all_structs, inner, key + ".", v or {}, limits, out)
            continue
        if inner:  # a list of tables: the lab value shown is the first entry's
            out.append(("list", key, ty, doc, value_text(v)))
            sub = (v or [{}])[0] if isinstance(v, list) else {}
            rows(all_structs, inner, key + "[].", sub, limits, out)
            continue
        out.append(("key", key, ty, doc, value_text(v), limits.get(key, "")))


def render(binary):
    effective = subprocess.run(
        [binary, "config"], check=True, capture_output=True, text=True
    ).stdout
    values = tomllib.loads(effective)
    all_structs = structs()
    out = []
    rows(all_structs, "Config", "", values, bounds(), out)
    lines = [
        "# Configuration reference",
        "",
        "Every key of an infotrack config file (TOML), generated from the config structs by",
        "`python3 scripts/config-doc.py` (`tests/config_doc.rs` fails when this file and the",
        "code disagree). *Lab value*: what the embedded default (`config/default.toml`, the",
        "paper's lab) means once defaults are filled in (`infotrack config` prints it; `infotrack",
        "config --config FILE` prints yours). Optional sections and keys may be left out: they",
        "take the lab value shown, or none. Units are SI unless the description says otherwise;",
        "frames are named in the key (`_enu`: world east-north-up, `_ned`: vehicle local",
        "north-east-down, `_frd`: body). Sizes and rates beyond the bound shown are refused at",
        "load, naming the key. Paths are relative to the config file.",
        "",
    ]
    table_open = False
    for r in out:
        if r[0] == "section":
            _, key, ty, doc = r
            lines += ["", f"## `[{key}]`", "", doc, ""]
            table_open = False
            continue
        if r[0] == "list":
            _, key, ty, doc, value = r
            lines += ["", f"### `[[{key}]]` ({value} in the lab)", "", doc, ""]
            table_open = False
            continue
        _, key, ty, doc, value, limit = r
        if not table_open:
            lines += ["| key | type | lab value | description | bound |", "|---|---|---|---|---|"]
            table_open = True
        doc = doc.replace("|", "\\|")
        lines.append(f"| `{key}` | `{ty}` | {value} | {doc} | {limit} |")
    return "\n".join(lines) + "\n"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--check", action="store_true")
    ap.add_argument("--bin", default=str(ROOT / "target/release/infotrack"))
    a = ap.parse_args()
    text = render(a.bin)
    path = ROOT / "docs/src/config.md"
    if a.check:
        old = path.read_text() if path.exists() else ""
        if old != text:
            import difflib

            diff = difflib.unified_diff(
                old.splitlines(), text.splitlines(), "docs/src/config.md", "from the code", lineterm=""
            )
            sys.exit(
                "docs/src/config.md disagrees with the config structs; run "
                "`python3 scripts/config-doc.py`:\n" + "\n".join(list(diff)[:60])
            )
        return
    path.parent.mkdir(exist_ok=True)
    path.write_text(text)


if __name__ == "__main__":
    main()
