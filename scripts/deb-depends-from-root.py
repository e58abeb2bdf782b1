#!/usr/bin/env python3
"""The Debian dependencies of a program's shared libraries, from the .deb files an arm64
root was extracted from (scripts/arm64-sysroot.sh): each library the program needs (its
NEEDED names, on standard input), as the package that holds it, at least at that package's
upstream version. Prints them as a Depends field's value; fails naming a library that no
package holds.

    objdump -p PROGRAM | sed -n 's/^ *NEEDED *//p' | python3 deb-depends-from-root.py DEBS
"""
import glob
import subprocess
import sys


def field(deb, name):
    out = subprocess.run(["dpkg-deb", "-f", deb, name], capture_output=True, text=True)
    return out.stdout.strip()


def file_names(deb):
    out = subprocess.run(["dpkg-deb", "-c", deb], capture_output=True, text=True).stdout
    return {line.rsplit("/", 1)[-1].split(" -> ")[0] for line in out.splitlines()}


def main():
    needed, debs = set(sys.stdin.read().split()), sys.argv[1]
    provider = {}
    # A run-time dependency is never a development package (libc6-dev also holds libc.so.6's
    # name, as a link).
    libraries = [d for d in sorted(glob.glob(debs + "/lib*.deb")) if "-dev_" not in d]
    for deb in libraries:
        for so in needed & file_names(deb):
            upstream = field(deb, "Version").split(":")[-1].rsplit("-", 1)[0]
            provider.setdefault(so, f"{field(deb, 'Package')} (>= {upstream})")
    missing = sorted(needed - provider.keys())
    if missing:
        sys.exit(f"deb-depends-from-root: no package in {debs} holds {', '.join(missing)}")
    print(", ".join(sorted(set(provider.values()))))


main()
