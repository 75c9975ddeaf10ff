#!/usr/bin/env python3
"""Checks that one program never holds two compilations of Eigen's inline code.

Eigen's inline functions (aligned_malloc/aligned_free among them) are compiled
differently for each vector width: 16-byte alignment under SSE, 32 under AVX, 64 under
AVX-512, with different allocators. Every translation unit that instantiates them emits
a weak copy and the linker keeps one, so a program whose objects were compiled with two
settings can allocate with one copy and free with the other (a prebuilt static Ceres
compiled for plain x86-64 inside an AVX-512 build corrupts the heap that way).

Checks, for a configured and built build directory:
  1. every object of ours that includes Eigen was compiled with the same vectorisation
     and alignment flags (-march/-m<isa>/-DEIGEN_*), from compile_commands.json and
     ninja's header dependencies;
  2. no library linked into any of our executables that we did not build (static
     archives on the link line, shared libraries ldd resolves) defines Eigen symbols.

Usage: eigen_odr_check.py BUILD_DIR
       eigen_odr_check.py --archive FILE   (check one prebuilt library; for the self-test)
Exit status 0: clean; 1: a finding (printed); 2: could not check.
"""

import concurrent.futures
import json
import os
import re
import shlex
import subprocess
import sys

# Flags that change what Eigen's inline code compiles to.
VECTOR_FLAG = re.compile(r"^(-march=|-mtune=|-mno-|-m(sse|ssse|avx|fma|f16c|bmi|popcnt|lzcnt|movbe|prefer-vector-width)|"
                         r"-DEIGEN_|-mfpmath)")


def run(args):
    return subprocess.run(args, check=True, capture_output=True, text=True).stdout


# Mangled names of functions and variables in namespace Eigen (and their guard variables,
# local statics and vtables); a function of the library's own that merely takes Eigen
# types (_Z5TwiceRKN5Eigen...) does not match and is not the hazard.
EIGEN_MANGLED = re.compile(r"^_Z(?:GV|TV|TI|TS)?Z?N?K?5Eigen")


def eigen_symbols(library, dynamic):
    """Eigen's own inline code that `library` carries: weak (W, V) or unique (u) definitions
    in namespace Eigen, demangled."""
    args = ["nm", "--defined-only"] + (["-D"] if dynamic else []) + [library]
    result = subprocess.run(args, capture_output=True, text=True)
    if result.returncode != 0:  # an unreadable library must not read as one without Eigen code
        sys.exit(f"eigen odr check: {' '.join(args)} failed: {result.stderr.strip()}")
    found = []
    for line in result.stdout.splitlines():
        parts = line.split()
        if len(parts) >= 3 and parts[1] in ("W", "V", "u") and EIGEN_MANGLED.match(parts[2]):
            found.append(parts[2])
    return [run(["c++filt", name]).strip() for name in found[:1]] + found[1:]


def vector_flags(command):
    return tuple(sorted({token for token in command if VECTOR_FLAG.match(token)}))


def objects_including_eigen(build_dir):
    """Object paths (relative to build_dir) whose recorded header dependencies include Eigen."""
    deps = run(["ninja", "-C", build_dir, "-t", "deps"])
    with_eigen, current = set(), None
    for line in deps.splitlines():
        if line and not line[0].isspace():
            current = line.split(":", 1)[0]
        elif current and "/eigen3/" in line:
            with_eigen.add(current)
    return with_eigen


def check_translation_units(build_dir):
    with open(os.path.join(build_dir, "compile_commands.json")) as f:
        commands = json.load(f)
    with_eigen = objects_including_eigen(build_dir)
    settings = {}
    for entry in commands:
        command = entry.get("arguments") or shlex.split(entry["command"])
        output = command[command.index("-o") + 1] if "-o" in command else None
        if output is None or output not in with_eigen:
            continue
        settings.setdefault(vector_flags(command), []).append(entry["file"])
    if not with_eigen:
        return ["no object records an Eigen header: is the build complete (ninja -t deps)?"]
    if len(settings) > 1:
        lines = ["translation units that include Eigen were compiled with different vector settings:"]
        for flags, files in settings.items():
            lines.append(f"  {' '.join(flags) or '(none)'}: {len(files)} files, e.g. {files[0]}")
        return lines
    flags = next(iter(settings))
    print(f"ok: {sum(len(v) for v in settings.values())} translation units with Eigen, one setting: {' '.join(flags)}")
    return []


def executables(build_dir):
    bin_dir = os.path.join(build_dir, "bin")
    for name in sorted(os.listdir(bin_dir)):
        path = os.path.join(bin_dir, name)
        if os.path.isfile(path) and os.access(path, os.X_OK):
            yield name, path


def prebuilt_archives_by_executable(build_dir):
    """bin/NAME -> the static archives on its link line that were not built in build_dir."""
    root = os.path.realpath(build_dir)
    archives = {}
    for line in run(["ninja", "-C", build_dir, "-t", "commands"]).splitlines():
        tokens = shlex.split(line)
        if "-o" not in tokens or not tokens[tokens.index("-o") + 1].startswith("bin/"):
            continue
        found = set()
        for token in tokens:
            for part in token.split(","):  # -Wl,a,b
                if part.endswith(".a") and \
                        not os.path.realpath(os.path.join(build_dir, part)).startswith(root + os.sep):
                    found.add(part)
        archives[os.path.basename(tokens[tokens.index("-o") + 1])] = found
    return archives


def shared_libraries(path):
    libraries = set()
    for line in run(["ldd", path]).splitlines():
        match = re.search(r"=> (/\S+)", line)
        if match:
            libraries.add(match.group(1))
    return libraries


def check_libraries(build_dir):
    findings = []
    archives = prebuilt_archives_by_executable(build_dir)
    programs = list(executables(build_dir))
    with concurrent.futures.ThreadPoolExecutor() as pool:
        linked = dict(zip([name for name, _ in programs], pool.map(shared_libraries, [p for _, p in programs])))
        libraries = {(a, False) for name in linked for a in archives.get(name, ())} | \
                    {(s, True) for name in linked for s in linked[name]}
        checked = dict(zip(libraries, pool.map(lambda item: eigen_symbols(*item), libraries)))
    for name in linked:
        for item in sorted({(a, False) for a in archives.get(name, ())} | {(s, True) for s in linked[name]}):
            if checked[item]:
                findings.append(f"{name} links {item[0]}, which defines Eigen code compiled with its own "
                                f"settings, e.g. {checked[item][0]}")
    if not findings:
        print(f"ok: {len(programs)} programs, {len(checked)} prebuilt libraries without Eigen code")
    return findings


def main(argv):
    if len(argv) == 3 and argv[1] == "--archive":
        symbols = eigen_symbols(argv[2], dynamic=argv[2].endswith(".so") or ".so." in argv[2])
        if symbols:
            print(f"{argv[2]} defines Eigen code, e.g. {symbols[0]}")
            return 1
        print(f"ok: {argv[2]} defines no Eigen code")
        return 0
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    try:
        findings = check_translation_units(argv[1]) + check_libraries(argv[1])
    except (OSError, subprocess.CalledProcessError, KeyError, ValueError) as error:
        print(f"could not check: {error}", file=sys.stderr)
        return 2
    for line in findings:
        print(line)
    return 1 if findings else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
