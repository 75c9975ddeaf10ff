#!/usr/bin/env python3
"""Prints the loopback/dev variant of the compose stack (up.sh --plaintext).

    plaintext-variant.py < nupmpc-stack.yaml > plaintext.yaml

Derived from the secure stack rather than kept as a second file, so the two differ only in
what this removes: the replicas' and the balancer's TLS, token and trusted-balancer settings
(every environment variable below) and the volumes that carry their files. The balancer's
host port is then published on 127.0.0.1 only: plaintext never leaves the machine, and a
replica accepts no bearer token over a non-loopback plaintext connection anyway.
"""
import sys

import yaml

SECURE_ONLY = {
    "NUPMPC_TLS_CERT_FILE", "NUPMPC_TLS_KEY_FILE", "NUPMPC_TLS_RELOAD_INTERVAL_S", "NUPMPC_TLS_CLIENT_CA_FILE",
    "NUPMPC_AUTH_TOKENS_FILE", "NUPMPC_TRUSTED_BALANCER_SUBJECT",
    "NUPMPC_BALANCER_TLS_CRT", "NUPMPC_BALANCER_CLIENT_CA", "NUPMPC_BALANCER_REPLICA_CA",
    "NUPMPC_BALANCER_REPLICA_NAME", "NUPMPC_BALANCER_CLIENT_CRT",
}


def plaintext(pod):
    spec = pod["spec"]
    for container in spec["containers"]:
        if "env" not in container:
            continue
        container["env"] = [e for e in container.get("env", []) if e["name"] not in SECURE_ONLY]
        # A secure setting added to the stack but not to SECURE_ONLY would leave TLS half on.
        left = [e["name"] for e in container["env"]
                if any(word in e["name"] for word in ("TLS", "TOKEN", "TRUSTED", "_CA", "_CRT"))
                or "/etc/nupmpc/tls" in str(e.get("value", ""))]
        if left:
            sys.exit(f"plaintext-variant.py: {container['name']}: {', '.join(left)} not removed: add to SECURE_ONLY")
    for container in spec["containers"]:
        container.pop("volumeMounts", None)
        for port in container.get("ports", []):
            if "hostPort" in port:
                port["hostIP"] = "127.0.0.1"
    spec.pop("volumes", None)
    pod["metadata"].setdefault("labels", {})["nupmpc.io/variant"] = "plaintext"
    return pod


def main():
    pod = yaml.safe_load(sys.stdin)
    yaml.safe_dump(plaintext(pod), sys.stdout, sort_keys=False)


if __name__ == "__main__":
    main()
