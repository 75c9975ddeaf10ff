#!/usr/bin/env python3
"""The TSan triage dismisses only what it is there to dismiss: a race between two pieces of
gRPC's inline code passes, and so does gRPC's virtual call of a reaction against the
reactor's constructor; the same log plus a race with our code on one side, or a report that
is not a race, fails. A report without a source line in its stacks (no symbolizer) is
neither dismissed nor a finding: it fails as not judged. Reports are in TSan's own format.

    tsan_triage_selftest.py
"""
import pathlib
import subprocess
import sys
import tempfile

TRIAGE = pathlib.Path(__file__).with_name("tsan_triage.py")


def report(kind, first, second):
    return (
        "==================\n"
        f"WARNING: ThreadSanitizer: {kind} (pid=42)\n"
        "  Read of size 8 at 0x7b5400040600 by thread T3:\n"
        f"    #0 swap /usr/bin/../lib/gcc/x86_64-linux-gnu/12/../../../../include/c++/12/bits/move.h:206:11 (t+0x1)\n"
        f"    #1 {first} (t+0x2)\n"
        "\n"
        "  Previous write of size 8 at 0x7b5400040600 by thread T9:\n"
        f"    #0 {second} (t+0x3)\n"
        "    #1 <null> <null> (libgrpc++.so.1.51+0xa21ed)\n"
        "\n"
        "  Location is heap block of size 568 at 0x7b5400040600 allocated by thread T9:\n"
        "    #0 operator new(unsigned long) <null> (t+0x4)\n"
        "\n"
        "SUMMARY: ThreadSanitizer: data race\n"
        "==================\n")


GRPC = "grpc::internal::CallbackWithSuccessTag::Run(bool) /usr/include/grpcpp/support/callback_common.h:202:21"
GRPC2 = "Set /usr/include/grpcpp/support/callback_common.h:168:10"
OURS = "nupmpc::server::ControlStream::OnDone() /work/x/server/control_stream.cc:326:63"


def triage(*logs):
    with tempfile.TemporaryDirectory() as work:
        for i, text in enumerate(logs):
            pathlib.Path(work, f"report.{i}").write_text(text)
        return subprocess.run([sys.executable, str(TRIAGE), work], capture_output=True, text=True)


def expect(result, code, needle):
    if result.returncode != code or needle not in result.stdout:
        print(f"FAIL: expected exit {code} and '{needle}', got {result.returncode}:\n{result.stdout}")
        sys.exit(1)


third_party = report("data race", GRPC, GRPC2)
expect(triage(third_party), 0, "1 reports dismissed as grpc")
expect(triage(third_party, report("data race", OURS, GRPC2)), 1, "1 findings")
expect(triage(report("data race", GRPC, OURS)), 1, "1 findings")
expect(triage(report("heap-use-after-free", GRPC, GRPC2)), 1, "1 findings")
# gRPC's virtual call of a reaction against the reactor's constructor: dismissed; against any
# other function of ours: a finding.
VPTR = "data race on vptr (ctor/dtor vs virtual call)"
CTOR = "nupmpc::server::UnaryCall<nupmpc::v1::SolveRequest, nupmpc::v1::SolveResponse>::UnaryCall(int) /w/server/unary_call.h:129:7"
expect(triage(report(VPTR, GRPC, CTOR)), 0, "1 reports dismissed as grpc-dispatch")
expect(triage(report(VPTR, GRPC, OURS)), 1, "1 findings")
# Without llvm-symbolizer every frame reads "<null> <null> (module+offset)": not judged.
UNSYMBOLIZED = report("data race", "<null> <null>", "<null> <null>").replace(
    "swap /usr/bin/../lib/gcc/x86_64-linux-gnu/12/../../../../include/c++/12/bits/move.h:206:11", "<null> <null>")
expect(triage(UNSYMBOLIZED), 1, "1 reports NOT JUDGED")
expect(triage(UNSYMBOLIZED), 1, "0 reports dismissed as grpc")
expect(triage(UNSYMBOLIZED), 1, "0 findings")
expect(triage(third_party, UNSYMBOLIZED), 1, "1 reports dismissed as grpc")
expect(triage(report("heap-use-after-free", "<null> <null>", "<null> <null>").replace(
    "swap /usr/bin/../lib/gcc/x86_64-linux-gnu/12/../../../../include/c++/12/bits/move.h:206:11", "<null> <null>")),
    1, "1 reports NOT JUDGED")
print("tsan triage self-test: passed")
