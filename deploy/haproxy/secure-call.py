#!/usr/bin/env python3
"""One nupmpc call with chosen credentials and headers; prints its status code name.

    secure-call.py --target HOST:PORT [--ca FILE] [--cert FILE --key FILE] [--token-file FILE]
                   [--forge SUBJECT] [--plaintext] ACTION

ACTION: info | list | create INSTANCE | get ID | close ID. `create` draws the session id
and prints "OK ID"; `list` prints "OK COUNT"; every call addressed by an id carries it in
x-nupmpc-session, so a balancer routes it to the replica holding the session.
--forge SUBJECT sends the header x-nupmpc-client-subject: SUBJECT as a client that tries
to pass for another caller would; --plaintext speaks plaintext HTTP/2 instead of TLS.
Used by deploy/scaleout-secure-test.sh; needs the generated stubs (build/python) and
client/python on PYTHONPATH.
"""
import argparse
import secrets
import sys

import grpc
from nupmpc._proto import pb, pb_grpc
from nupmpc.instance import load_instance


def read(path):
    with open(path, "rb") as f:
        return f.read()


def channel_for(args):
    if args.plaintext:
        return grpc.insecure_channel(args.target)
    if (args.cert is None) != (args.key is None):
        raise SystemExit("secure-call.py: --cert and --key: give both or neither")
    credentials = grpc.ssl_channel_credentials(
        root_certificates=read(args.ca) if args.ca else None,
        private_key=read(args.key) if args.key else None,
        certificate_chain=read(args.cert) if args.cert else None)
    return grpc.secure_channel(args.target, credentials)


def main():
    parser = argparse.ArgumentParser(usage=__doc__)
    parser.add_argument("--target", required=True)
    parser.add_argument("--ca")
    parser.add_argument("--cert")
    parser.add_argument("--key")
    parser.add_argument("--token-file")
    parser.add_argument("--forge")
    parser.add_argument("--plaintext", action="store_true")
    parser.add_argument("action", choices=["info", "list", "create", "get", "close"])
    parser.add_argument("argument", nargs="?")
    args = parser.parse_args()
    if args.action in ("create", "get", "close") and not args.argument:
        parser.error(f"{args.action}: needs {'INSTANCE' if args.action == 'create' else 'ID'}")
    metadata = []
    if args.token_file:
        metadata.append(("authorization", "Bearer " + read(args.token_file).decode().splitlines()[0].strip()))
    if args.forge is not None:
        metadata.append(("x-nupmpc-client-subject", args.forge))
    session_id = secrets.token_hex(16) if args.action == "create" else args.argument
    if args.action in ("create", "get", "close"):
        metadata.append(("x-nupmpc-session", session_id))
    with channel_for(args) as channel:
        stub = pb_grpc.MpcServiceStub(channel)
        try:
            if args.action == "info":
                stub.GetServerInfo(pb.GetServerInfoRequest(), metadata=metadata, timeout=10)
                print("OK")
            elif args.action == "list":
                answer = stub.ListSessions(pb.ListSessionsRequest(), metadata=metadata, timeout=10)
                print("OK", len(answer.sessions))
            elif args.action == "create":
                request = pb.CreateSessionRequest(spec=load_instance(args.argument).spec, session_id=session_id)
                print("OK", stub.CreateSession(request, metadata=metadata, timeout=10).session_id)
            elif args.action == "get":
                stub.GetSession(pb.GetSessionRequest(session_id=session_id), metadata=metadata, timeout=10)
                print("OK")
            else:
                stub.CloseSession(pb.CloseSessionRequest(session_id=session_id), metadata=metadata, timeout=10)
                print("OK")
        except grpc.RpcError as error:
            print(error.code().name)
    return 0


if __name__ == "__main__":
    sys.exit(main())
