#!/usr/bin/env python3
"""The layering rules of ../shared/docs/architecture.md, checked on every #include.

    layering_check.py SOURCE_DIR

Every C++ file of the repository belongs to a room (its folder: core/, core/gp/,
core/examples/, server/, client/, loadtest/ and its subfolders, cli/, tests/); each room
may include only the rooms it depends on, and some external libraries are kept out of some
rooms (the core has no gRPC, protobuf, logging, JSON or optimiser libraries). Outside core/
(and its GP library) the core is reached through its public headers only: the facade
core/nupmpc.h and core/public/ (the room "core/public"). core/public/standalone/ holds the
headers that need nothing but the C++ standard library: the client, which does not link the
core, shares the step-control rules through them. The build
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
                "server/sessions", "server/snapshots", "server/state", "server/rpc", "server"]
ROOMS = ["core/gp", "core/examples", "core/public/standalone", "core/public", "core", "cli", "proto", *SERVER_ROOMS, "client", "loadtest/instances",
         "loadtest/bench/gp", "loadtest/bench", "loadtest", "tests/fuzz", "tests"]
# What a session is made of: the rooms below the state every RPC shares.
# The core's public headers: the facade core/nupmpc.h and core/public/ (forwarding to the
# rooms inside the core, or standing alone).
PUBLIC_CORE = {"core/public", "core/public/standalone"}
FACADE = "core/nupmpc.h"
SESSION_ROOMS = {"server/sessions", "server/convert", "server/scheduling", "server/auth", "server/observability",
                 "core/gp", "proto"} | PUBLIC_CORE

ALLOWED = {
    # nupmpc_core: Eigen and Abseil only; never the GP library or the seed applications.
    "core": {"core"} | PUBLIC_CORE,
    "core/public": {"core"} | PUBLIC_CORE,
    # The C++ standard library only (STANDARD_LIBRARY_ONLY).
    "core/public/standalone": {"core/public/standalone"},
    "core/gp": {"core", "core/gp"} | PUBLIC_CORE,
    # The seed applications: programs on top of the core's public API (their command line from cli/).
    "core/examples": {"core/gp", "core/examples", "cli"} | PUBLIC_CORE,
    "cli": {"cli"},
    # Conversion sees the core and the API, never gRPC (EXTERNAL_FORBIDDEN) or sessions.
    "server/convert": {"server/convert", "core/gp", "proto"} | PUBLIC_CORE,
    "server/scheduling": {"server/scheduling"},
    "server/observability": {"server/observability", "proto"},
    "server/http": {"server/http"},
    "server/auth": {"server/auth"},
    "server/sessions": SESSION_ROOMS,
    "server/snapshots": SESSION_ROOMS | {"server/snapshots"},
    "server/state": SESSION_ROOMS | {"server/snapshots", "server/state"},
    "server/rpc": SESSION_ROOMS | {"server/snapshots", "server/state", "server/rpc"},
    # The process: everything of the server, and the command line.
    "server": set(SERVER_ROOMS) | {"core/gp", "proto", "cli"} | PUBLIC_CORE,
    # The client library and the nupmpc CLI: proto + gRPC only, and the core's standalone
    # rules (NonlinearSession's step control).
    "client": {"client", "proto", "cli", "core/public/standalone"},
    # nupmpc-loadtest; its core peer builds the session the server builds (server/).
    "loadtest": {"loadtest", "loadtest/instances", "client", "proto", "cli", *SERVER_ROOMS} | PUBLIC_CORE,
    # The shared test data: instances through client/'s reader and the server's conversion.
    "loadtest/instances": {"loadtest/instances", "client", "server/convert", "proto"} | PUBLIC_CORE,
    "loadtest/bench": {"loadtest/bench", "loadtest/instances", "cli"} | PUBLIC_CORE,
    "loadtest/bench/gp": {"loadtest/bench/gp", "core/gp", "core/examples", "cli"} | PUBLIC_CORE,
    # The fuzz targets drive the server's code paths and the client's readers in-process.
    "tests/fuzz": {"tests/fuzz", "client", "proto", *SERVER_ROOMS} | PUBLIC_CORE,
    "tests": set(ROOMS),
}

# External headers kept out of a room (prefixes of the included path).
NOT_IN_CORE = ("grpc", "grpcpp/", "google/protobuf/", "spdlog/", "nlohmann/", "ceres/", "Ip")
NO_GRPC = ("grpc", "grpcpp/")
EXTERNAL_FORBIDDEN = {
    "core": NOT_IN_CORE + ("lbfgs.h",),
    "core/public": NOT_IN_CORE + ("lbfgs.h",),
    "core/gp": NOT_IN_CORE,
    "server/convert": NO_GRPC,
    "server/scheduling": NO_GRPC + ("google/protobuf/",),
    "server/http": NO_GRPC + ("google/protobuf/", "spdlog/"),
    "client": ("Eigen/", "spdlog/", "nlohmann/", "ceres/", "lbfgs.h"),
}

# Rooms whose files include nothing but the C++ standard library (<name>, no folder, no suffix).
STANDARD_LIBRARY_ONLY = {"core/public/standalone"}
STANDARD_HEADER = re.compile(r"^[a-z_]+$")

INCLUDE = re.compile(r'^\s*#\s*include\s*([<"])([^">]+)[">]')
SOURCE_SUFFIXES = (".h", ".hpp", ".cc", ".cpp", ".cxx", ".c", ".inc")
ROOT_EXPORT = re.compile(r"include_directories\s*\([^)]*\$\{(?:PROJECT|CMAKE)_SOURCE_DIR\}\s*[)\s]", re.S)


def room_of(path):
    """The room of a repository-relative path (or an included path), or None."""
    if path.startswith("nupmpc/"):
        return "proto"
    if path == FACADE:
        return "core/public"
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
                    if room in STANDARD_LIBRARY_ONLY and target != room and not (
                            m.group(1) == "<" and STANDARD_HEADER.match(included)):
                        findings.append(f"{where}: {room}/ may include the C++ standard library only")
                    elif target is not None:
                        if target == "core" and "core" not in ALLOWED[room] and "core/public" in ALLOWED[room]:
                            findings.append(f"{where}: outside core/, only the core's public headers ({FACADE}, "
                                            "core/public/) may be included")
                        elif target not in ALLOWED[room]:
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
