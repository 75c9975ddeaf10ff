#!/usr/bin/env python3
"""Triage of ThreadSanitizer reports (deploy/test-sanitizers.sh, the TSan stage).

    tsan_triage.py REPORT_DIR

Debian's gRPC and protobuf libraries are not compiled with -fsanitize=thread, so the
synchronisation with which libgrpc hands a call's objects from one of its threads to the
next is invisible to TSan. The inline parts of their headers are compiled into our
instrumented code, so TSan reports those hand-overs as races between two pieces of gRPC's or
protobuf's own code. Such a report is dismissed, by the rule below that names it; every
other report (a race with our code on either side, a use after free, a lock-order
inversion, ...) is a finding and fails the run. Our reactors state gRPC's ordering of their
own reactions with annotations (proto/nupmpc/grpc_handover.h), so reports about their fields are
findings too.

A report is judged only when its stacks are symbolized: every access stack (or, for reports
of another kind, the report) has a frame with a source line. Without llvm-symbolizer every
frame reads "<null>", and such a report is neither a finding nor dismissed: it is counted
as unreadable and fails the run with the cause.

A report's accesses are attributed to the first stack frame outside the C++ standard
library and Abseil's vocabulary headers (a std::function or absl::string_view copied by
someone else's code belongs to that code).
"""
import collections
import pathlib
import re
import sys

# Frames that belong to whoever called them.
PASS_THROUGH = ("/include/c++/", "/usr/include/absl/", "<null>")

# (name, reason, pattern of the attributed frame): a race is dismissed when both of its
# accesses are attributed to third-party code (counted under the first access's rule).
GRPC_HEADERS = re.compile(r"/usr/include/grpc(pp)?/")
THIRD_PARTY = [
    ("grpc", "gRPC's inline callback and call-operation code (/usr/include/grpcpp) handing a call "
     "between libgrpc's threads through libgrpc's uninstrumented synchronisation",
     GRPC_HEADERS),
    ("protobuf", "messages gRPC parses and serialises on its threads (protobuf's headers and the "
     "generated code), handed over by libgrpc",
     re.compile(r"/usr/include/google/protobuf/|\.pb\.(cc|h):")),
]

RACE_KINDS = ("data race", "data race on vptr (ctor/dtor vs virtual call)")

# gRPC calling a reaction (a virtual call, in its inline code on one of its threads) of a
# reactor our handler constructed and handed over: the vtable read precedes the reaction's
# own annotation (proto/nupmpc/grpc_handover.h), so TSan cannot see libgrpc's ordering.
REACTOR_DISPATCH = ("grpc-dispatch", "gRPC calling a reaction of a reactor the handler constructed and "
                    "handed over (the vtable read comes before the reaction's annotation)")
CONSTRUCTOR = re.compile(r"\b(\w+)(<.*>)?::\1\(")


def split_reports(text):
    """The reports in one TSan log: (kind, [stack of each access])."""
    for block in re.split(r"={18}\nWARNING: ThreadSanitizer: ", text)[1:]:
        block = block.split("\n={18}")[0]
        kind = re.sub(r" \(pid=\d+\)", "", block.split("\n", 1)[0]).strip()
        body = re.split(r"\n\n  (?:Location is|Mutex|Thread|Issue is)", block)[0]
        parts = re.split(r"\n  (?:Previous )?(?:[Aa]tomic )?(?:[Ww]rite|[Rr]ead)[^\n]*:\n", body)
        stacks = [re.findall(r"#\d+ ([^\n]*)", part) for part in parts[1:3]]
        yield kind, stacks, block


SOURCE_LINE = re.compile(r" \S+:\d+(:\d+)? \(")


def symbolized(stacks, block):
    """Whether the report can be read: the accessing code is instrumented and compiled with
    line tables, so only a missing symbolizer leaves a stack without any source line."""
    if stacks:
        return all(any(SOURCE_LINE.search(frame) for frame in stack) for stack in stacks)
    return any(SOURCE_LINE.search(line) for line in re.findall(r"#\d+ [^\n]*", block))


def attributed(stack):
    for frame in stack:
        if not any(p in frame for p in PASS_THROUGH):
            return frame
    return stack[0] if stack else "?"


def rule_of(kind, stacks):
    """The third-party rule dismissing this report, or None for a finding."""
    if kind not in RACE_KINDS or len(stacks) != 2:
        return None
    frames = [attributed(s) for s in stacks]
    if kind.startswith("data race on vptr") and GRPC_HEADERS.search(frames[0]) and CONSTRUCTOR.search(frames[1]):
        return REACTOR_DISPATCH[0]
    names = []
    for frame in frames:
        name = next((n for n, _, pattern in THIRD_PARTY if pattern.search(frame)), None)
        if name is None:
            return None
        names.append(name)
    return names[0]


def main(argv):
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    dismissed = collections.Counter()
    findings = []
    unreadable = 0
    logs = sorted(pathlib.Path(argv[1]).glob("*"))
    for log in logs:
        for kind, stacks, block in split_reports(log.read_text(errors="replace")):
            if not symbolized(stacks, block):
                unreadable += 1
                continue
            rule = rule_of(kind, stacks)
            if rule is None:
                findings.append((log.name, block))
            else:
                dismissed[rule] += 1
    for name, reason in [(n, r) for n, r, _ in THIRD_PARTY] + [REACTOR_DISPATCH]:
        print(f"tsan triage: {dismissed[name]:5d} reports dismissed as {name}: {reason}")
    print(f"tsan triage: {len(findings)} findings in {len(logs)} logs")
    if unreadable:
        print(f"tsan triage: {unreadable} reports NOT JUDGED: their stacks are not symbolized (no source "
              "line in any frame; is llvm-symbolizer, package llvm-14, installed?)")
    for log_name, block in findings[:20]:
        print(f"--- finding in {log_name}:\nWARNING: ThreadSanitizer: {block}\n")
    return 1 if findings or unreadable else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
