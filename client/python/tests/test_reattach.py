"""How a Session gets its session back after its stream broke, against a scripted Control
service in this process (the Python mirror of tests/client/session_reattach_test.cc): the
session is asked for by its id first, on a stream routed by that id; a server that hands it
back keeps it (same id) and gets the unanswered step exactly once; NOT_FOUND and
FAILED_PRECONDITION re-create it from the spec. Every plan is its own step's (the scripted
answer's objective is the step's state)."""

import threading
from concurrent import futures

import grpc
import pytest

import nupmpc
from nupmpc._proto import pb, pb_grpc


class ScriptedControl(pb_grpc.MpcServiceServicer):
    """Answers every step at once, except state 2 on the first stream, which ends the
    stream with UNAVAILABLE (a server that went away with the step). An attach by id gets
    `attach_by_id` (OK: the server kept the session)."""

    def __init__(self, attach_by_id=grpc.StatusCode.OK):
        self.attach_by_id = attach_by_id
        self.lock = threading.Lock()
        self.attaches = []   # (session_id or "" when created, routing header, accepted)
        self.received = []   # (stream number, x0)
        self.streams = 0

    def Control(self, request_iterator, context):
        header = dict(context.invocation_metadata()).get("x-nupmpc-session", "")
        first = next(request_iterator)
        by_id = first.WhichOneof("attach") == "session_id"
        accepted = not by_id or self.attach_by_id == grpc.StatusCode.OK
        with self.lock:
            self.attaches.append((first.session_id if by_id else "", header, accepted))
            if accepted:
                self.streams += 1
                stream = self.streams
        if not accepted:
            context.abort(self.attach_by_id, "not here")
        session_id = first.session_id if by_id else f"{stream:032x}"
        yield pb.ControlResponse(sequence=first.sequence, session_id=session_id)
        for request in request_iterator:
            x0 = request.step.state[0]
            with self.lock:
                self.received.append((stream, x0))
            if stream == 1 and x0 == 2.0:
                context.abort(grpc.StatusCode.UNAVAILABLE, "the scripted server went away")
            yield pb.ControlResponse(sequence=request.sequence, result=pb.SolveResult(
                status=pb.SOLVE_STATUS_CONVERGED, has_plan=True, objective=x0, inputs=[x0], states=[x0, x0],
                outputs=[x0, x0]))


@pytest.fixture
def scripted(request):
    service = ScriptedControl(request.param)
    server = grpc.server(futures.ThreadPoolExecutor(max_workers=8))
    pb_grpc.add_MpcServiceServicer_to_server(service, server)
    port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    yield service, f"127.0.0.1:{port}"
    server.stop(0.1)


PROBLEM = nupmpc.Problem([[1.0]], [[1.0]], [[1.0]], horizon=1, x0=[0.0])


def _step_through_the_break(target):
    """Steps 1 (answered) and 2 (its stream breaks); returns the session and step 2's plan."""
    attempts = []
    client = nupmpc.connect(target)
    session = client.session(PROBLEM, nupmpc.ReconnectOptions(initial_backoff_s=0.01, on_attempt=attempts.append))
    first_id = session.id
    assert session.step([1.0]).objective == 1.0
    return client, session, first_id, session.step([2.0]), attempts


@pytest.mark.parametrize("scripted", [grpc.StatusCode.OK], indirect=True)
def test_a_server_that_kept_the_session_gets_it_back_by_id_and_the_unanswered_step_once(scripted):
    service, target = scripted
    client, session, first_id, plan, attempts = _step_through_the_break(target)
    try:
        assert plan.objective == 2.0, "the plan is not the resent step's own"
        assert session.id == first_id
        assert (session.stats.reconnects, session.stats.reattached, session.stats.recreated) == (1, 1, 0)
        # Created once, then attached by its id with the routing header a balancer hashes.
        assert service.attaches == [("", "", True), (first_id, first_id, True)]
        assert service.received.count((1, 2.0)) == 1 and service.received.count((2, 2.0)) == 1
        assert (attempts[-1].path, attempts[-1].attach_by_id) == ("reattached", "OK")
        assert session.step([3.0]).objective == 3.0 and (2, 3.0) in service.received
        session.close()
    finally:
        client.close()


@pytest.mark.parametrize("scripted", [grpc.StatusCode.NOT_FOUND, grpc.StatusCode.FAILED_PRECONDITION],
                         indirect=True)
def test_a_session_the_server_does_not_hand_back_is_recreated_from_the_spec(scripted):
    service, target = scripted
    client, session, first_id, plan, attempts = _step_through_the_break(target)
    try:
        assert plan.objective == 2.0
        assert session.id != first_id
        assert (session.stats.reconnects, session.stats.reattached, session.stats.recreated) == (1, 0, 1)
        assert session.stats.attempts == 1  # the re-creation is part of the attempt whose attach missed
        assert service.attaches == [("", "", True), (first_id, first_id, False), ("", "", True)]
        assert service.received.count((2, 2.0)) == 1
        assert (attempts[-1].path, attempts[-1].attach_by_id) == ("recreated", service.attach_by_id.name)
        session.close()
    finally:
        client.close()
