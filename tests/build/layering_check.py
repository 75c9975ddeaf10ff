#!/usr/bin/env python3
"""The layering rules of ../shared/docs/architecture.md, checked on every #include.

    layering_check.py SOURCE_DIR

Every C++ file of the repository belongs to a room (its folder: core/, core/gp/,
core/examples/, server/, client/, loadtest/ and its subfolders, cli/, tests/); each room
may include only the rooms it depends on, and some external libraries are kept out of some
rooms (the core has no gRPC, protobuf, logging, JSON or optimiser libraries). The build
enforces the same through per-target include roots (cmake/include_roots.cmake); this check
also names the rule, covers headers no target compiles on their own, and refuses a
CMakeLists.txt that exports the repository root as an include directory. Exit status 1
and one line per finding when anything is forbidden.
"""

import os
import re
import sys

# Most specific first: a file (or an included path) belongs to the first room whose folder
# is a prefix of it. "proto" stands for the generated headers nupmpc/v1/*.pb.h and the API's
# shared gRPC helper nupmpc/grpc_handover.h.
# The server's folders, lowest first (server/CMakeLists.txt says what each holds).
SERVER_ROOMS = ["server/convert", "server/scheduling", "server/observability", "server/http", "server/auth",
                "server/sessions", "server/state", "server/rpc", "server"]
ROOMS = ["core/gp", "core/examples", "core", "cli", "proto", *SERVER_ROOMS, "client", "loadtest/instances",
         "loadtest/bench/gp", "loadtest/bench", "loadtest", "tests/fuzz", "tests"]
# What a session is made of: the rooms below the state every RPC shares.
SESSION_ROOMS = {"server/sessions", "server/convert", "server/scheduling", "server/auth", "server/observability",
                 "core", "core/gp", "proto"}

ALLOWED = {
    # nupmpc_core: Eigen and Abseil only; never the GP library or the seed applications.
    "core": {"core"},
    "core/gp": {"core", "core/gp"},
    # The seed applications: programs on top of the core (their command line from cli/).
    "core/examples": {"core", "core/gp", "core/examples", "cli"},
    "cli": {"cli"},
    # Conversion sees the core and the API, never gRPC (EXTERNAL_FORBIDDEN) or sessions.
    "server/convert": {"server/convert", "core", "core/gp", "proto"},
    "server/scheduling": {"server/scheduling"},
    "server/observability": {"server/observability", "proto"},
    "server/http": {"server/http"},
    "server/auth": {"server/auth"},
    "server/sessions": SESSION_ROOMS,
    "server/state": SESSION_ROOMS | {"server/state"},
    "server/rpc": SESSION_ROOMS | {"server/state", "server/rpc"},
    # The process: everything of the server, and the command line.
    "server": set(SERVER_ROOMS) | {"core", "core/gp", "proto", "cli"},
    # The client library and the nupmpc CLI: proto + gRPC only.
    "client": {"client", "proto", "cli"},
    # nupmpc-loadtest; its core peer builds the session the server builds (server/).
    "loadtest": {"loadtest", "loadtest/instances", "client", "proto", "cli", "core", *SERVER_ROOMS},
    # The shared test data: instances through client/'s reader and the server's conversion.
    "loadtest/instances": {"loadtest/instances", "client", "server/convert", "core", "proto"},
    "loadtest/bench": {"loadtest/bench", "loadtest/instances", "core", "cli"},
    "loadtest/bench/gp": {"loadtest/bench/gp", "core", "core/gp", "core/examples", "cli"},
    # The fuzz targets drive the server's code paths and the client's readers in-process.
    "tests/fuzz": {"tests/fuzz", "client", "proto", "core", *SERVER_ROOMS},
    "tests": set(ROOMS),
}

# External headers kept out of a room (prefixes of the included path).
NOT_IN_CORE = ("grpc", "grpcpp/", "google/protobuf/", "spdlog/", "nlohmann/", "ceres/", "Ip")
NO_GRPC = ("grpc", "grpcpp/")
EXTERNAL_FORBIDDEN = {
    "core": NOT_IN_CORE + ("lbfgs.h",),
    "core/gp": NOT_IN_CORE,
    "server/convert": NO_GRPC,
    "server/scheduling": NO_GRPC + ("google/protobuf/",),
    "server/http": NO_GRPC + ("google/protobuf/", "spdlog/"),
    "client": ("Eigen/", "spdlog/", "nlohmann/", "ceres/", "lbfgs.h"),
}

INCLUDE = re.compile(r'^\s*#\s*include\s*([<"])([^">]+)[">]')
SOURCE_SUFFIXES = (".h", ".hpp", ".cc", ".cpp", ".cxx", ".c", ".inc")
ROOT_EXPORT = re.compile(r"include_directories\s*\([^)]*\$\{(?:PROJECT|CMAKE)_SOURCE_DIR\}\s*[)\s]", re.S)


def room_of(path):
    """The room of a repository-relative path (or an included path), or None."""
    if path.startswith("nupmpc/"):
        return "proto"
    for room in ROOMS:
        if path == room or path.startswith(room + "/"):
            return room
    return None


def describe(rooms):
    return ", ".join(sorted(r + ("" if r == "proto" else "/") for r in rooms))


def check(source_dir):
    findings = []
    files = includes = 0
    for top, dirs, names in os.walk(source_dir):
        rel_top = os.path.relpath(top, source_dir)
        # Build trees and hidden folders are not sources.
        dirs[:] = sorted(d for d in dirs if not d.startswith(".") and not (rel_top == "." and d.startswith("build")))
        for name in sorted(names):
            rel = os.path.normpath(os.path.join(rel_top, name))
            if name == "CMakeLists.txt" or name.endswith(".cmake"):
                with open(os.path.join(top, name), encoding="utf-8", errors="replace") as f:
                    text = f.read()
                for m in ROOT_EXPORT.finditer(text):
                    line = text.count("\n", 0, m.start()) + 1
                    findings.append(f"{rel}:{line}: exports the repository root as an include directory "
                                    "(use nupmpc_include_root, cmake/include_roots.cmake)")
                continue
            if not name.endswith(SOURCE_SUFFIXES):
                continue
            room = room_of(rel)
            if room is None:
                continue
            files += 1
            with open(os.path.join(top, name), encoding="utf-8", errors="replace") as f:
                for number, line in enumerate(f, 1):
                    m = INCLUDE.match(line)
                    if not m:
                        continue
                    includes += 1
                    included = m.group(2)
                    close = '"' if m.group(1) == '"' else ">"
                    where = f"{rel}:{number}: #include {m.group(1)}{included}{close}"
                    if ".." in included.split("/"):
                        findings.append(f"{where}: relative paths out of the folder are not allowed")
                        continue
                    target = room_of(included)
                    if m.group(1) == '"' and os.path.exists(os.path.join(top, included)):
                        # Found beside the including file first (the compiler looks there
                        # before the include roots): its room is where it really is.
                        target = room_of(os.path.normpath(os.path.join(rel_top, included)))
                    if target is not None:
                        if target not in ALLOWED[room]:
                            findings.append(f"{where}: {room}/ may include {describe(ALLOWED[room])} only "
                                            f"(not {target}{'' if target == 'proto' else '/'})")
                    elif included.startswith(EXTERNAL_FORBIDDEN.get(room, ())):
                        findings.append(f"{where}: {room}/ must not depend on this library")
    return findings, files, includes


def main():
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    findings, files, includes = check(sys.argv[1])
    for f in findings:
        print(f)
    if findings:
        print(f"layering check: {len(findings)} finding(s) in {files} files", file=sys.stderr)
        return 1
    print(f"layering check: {files} files, {includes} includes, none forbidden")
    return 0


if __name__ == "__main__":
    sys.exit(main())
