#!/usr/bin/python3
"""The Prometheus files of deploy/prometheus/ against Debian's promtool and a real server:

  1. `promtool check config` of prometheus.yml and `promtool check rules` of the alerts;
  2. `promtool test rules`: the alerts' unit tests (nupmpc-alerts_test.yml);
  3. every nupmpc_* metric the rules read is one a real nupmpc-server exports (its /metrics
     after one solve), so a renamed metric cannot leave an alert silently empty.

    tests/deploy/prometheus_rules_check.py REPO   (env NUPMPC_SERVER_BINARY, NUPMPC_PYTHON_STUBS)"""

import os
import pathlib
import re
import subprocess
import sys
import urllib.request


def run(*command):
    done = subprocess.run(command, capture_output=True, text=True)
    print(done.stdout + done.stderr, end="")
    if done.returncode != 0:
        sys.exit(f"FAIL: {' '.join(command)} exited with {done.returncode}")


def exported_metric_names(repo):
    sys.path.insert(0, str(repo / "client" / "python"))
    sys.path.insert(0, os.environ.get("NUPMPC_PYTHON_STUBS", str(repo / "build" / "python")))
    import nupmpc
    from nupmpc.local_server import LocalServer, default_binary
    server = LocalServer(default_binary(), metrics=True)
    server.start()
    try:
        with nupmpc.connect(server.target) as client:
            client.solve_once(nupmpc.load_instance(repo / "benchmarks" / "masses_N30.json").problem)
        text = urllib.request.urlopen(f"{server.metrics_url}/metrics", timeout=5).read().decode()
    finally:
        server.stop()
    return {m.group(1) for m in re.finditer(r"^# TYPE (\S+) (\S+)", text, re.M)} | {
        f"{m.group(1)}_bucket" for m in re.finditer(r"^# TYPE (\S+) histogram", text, re.M)}


def main():
    repo = pathlib.Path(sys.argv[1]).resolve()
    directory = repo / "deploy" / "prometheus"
    run("promtool", "check", "config", str(directory / "prometheus.yml"))
    run("promtool", "check", "rules", str(directory / "nupmpc-alerts.yml"))
    run("promtool", "test", "rules", str(directory / "nupmpc-alerts_test.yml"))
    rules = (directory / "nupmpc-alerts.yml").read_text()
    used = set(re.findall(r"\b(nupmpc_[a-z_]+)", rules))
    exported = exported_metric_names(repo)
    missing = sorted(used - exported)
    print(f"rules read {len(used)} nupmpc metrics: {', '.join(sorted(used))}")
    if missing:
        sys.exit(f"FAIL: the rules read metrics the server does not export: {', '.join(missing)}")
    print("PASS: config, rules and their unit tests, and every metric the rules read is exported")


if __name__ == "__main__":
    main()
