#!/usr/bin/env python3
"""The nupmpc CLI links proto + gRPC only: no solver core, no GP library, no optimiser.

    cli_link_check.py BUILD_DIR BINARY

Reads the CLI's link command from the build system (build.ninja, or link.txt of the
Makefile generators) and fails when it names a forbidden library; then looks for symbols
of the core, the GP library and the server in the linked binary (a static library whose
objects were pulled in shows up there even if the link line were produced differently).
Prints the libraries of the link line.
"""

import os
import re
import subprocess
import sys

TARGET = "nupmpc"
# Archives and libraries the CLI must not link (file names, without directory).
FORBIDDEN_LIBRARIES = re.compile(
    r"^lib(nupmpc_core|nupmpc_gp|nupmpc_spec|nupmpc_server|nupmpc_instances|nupmpc_bench_lib|nupmpc_examples_lib|"
    r"nupmpc_gp_examples_lib|lbfgs|ceres|ipopt|spdlog)[.-]")
FORBIDDEN_SYMBOLS = re.compile(r"\bnupmpc::(core|gp|server|bench|examples)::|\blbfgs\b")


def ninja_link_line(build_dir):
    path = os.path.join(build_dir, "build.ninja")
    if not os.path.exists(path):
        return None
    block = []
    with open(path, encoding="utf-8", errors="replace") as f:
        inside = False
        for line in f:
            if line.startswith("build "):
                outputs = line.split(":", 1)[0].split()[1:]
                inside = any(os.path.basename(o) == TARGET and "CMakeFiles" not in o for o in outputs) and \
                    "LINKER" in line
            if inside:
                if not line.strip():
                    break
                block.append(line.strip())
    return " ".join(block) if block else None


def make_link_line(build_dir):
    for top, _, names in os.walk(build_dir):
        if os.path.basename(top) == f"{TARGET}.dir" and "link.txt" in names:
            with open(os.path.join(top, "link.txt"), encoding="utf-8") as f:
                return f.read()
    return None


def main():
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    build_dir, binary = sys.argv[1], sys.argv[2]
    line = ninja_link_line(build_dir) or make_link_line(build_dir)
    if line is None:
        print(f"cli link check: no link command for {TARGET} in {build_dir}", file=sys.stderr)
        return 1
    tokens = re.split(r"\s+", line.replace("$\n", " "))
    libraries = []
    for t in tokens:
        t = t.strip("$")
        name = os.path.basename(t)
        if name.startswith("lib") and (name.endswith(".a") or ".so" in name):
            libraries.append(name)
        elif t.startswith("-l"):
            libraries.append("lib" + t[2:] + ".so")
    # Unique, in link order.
    seen = set()
    libraries = [x for x in libraries if not (x in seen or seen.add(x))]
    print(f"{TARGET} links: {' '.join(libraries)}")
    failures = [x for x in libraries if FORBIDDEN_LIBRARIES.match(x)]
    for x in failures:
        print(f"FORBIDDEN: the link line of {TARGET} names {x}")

    if not os.path.exists(binary):
        print(f"cli link check: {binary} does not exist (build it first)", file=sys.stderr)
        return 1
    symbols = subprocess.run(["nm", "-C", binary], capture_output=True, text=True, check=True).stdout
    bad_symbols = sorted({m.group(0) for m in FORBIDDEN_SYMBOLS.finditer(symbols)})
    for s in bad_symbols:
        print(f"FORBIDDEN: {binary} holds symbols of {s}")
    if failures or bad_symbols:
        return 1
    print(f"cli link check: {TARGET} links no core, GP, server, optimiser or test-data library, "
          "and holds none of their symbols")
    return 0


if __name__ == "__main__":
    sys.exit(main())
