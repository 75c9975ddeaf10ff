#!/usr/bin/python3
"""What metrics and TLS cost: nupmpc-loadtest against servers that differ only in them.

Starts four nupmpc-servers on loopback ports (built binaries in build/bin):
  plain        no metrics endpoint, plaintext
  metrics      --metrics_address, scraped every second (Prometheus scrapes every 15 s)
  tls          TLS (a P-256 certificate made here with openssl)
  tls+token    TLS and bearer tokens (--auth_tokens_file)
and runs the closed-loop masses_N30 load at each concurrency against each of them in
turn, several rounds interleaved (so drift of a shared machine hits every server alike),
and prints the median of the rounds per server and level, with the ratio to `plain`.
Only one server has load at a time; the others sit idle.

  deploy/security-overhead.py [--rounds 5] [--duration_s 3] [--levels 1,8] [--pin]

--pin: every server on CPU 0, the load generator on CPU 1 (taskset), so the servers' work
is measured on a core of its own. The order of the servers rotates from round to round.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.join(ROOT, "build", "bin")
TOKEN = "overhead-0123456789abcdef0123456789"
sys.path.insert(0, os.path.join(ROOT, "tests", "util"))
from loopback_port import free_port  # noqa: E402


def make_certificate(directory):
    key, cert = os.path.join(directory, "server.key"), os.path.join(directory, "server.pem")
    subprocess.run(["openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
                    "-days", "1", "-keyout", key, "-out", cert, "-subj", "/CN=nupmpc-server",
                    "-addext", "subjectAltName=IP:127.0.0.1"], check=True, capture_output=True)
    return cert, key


def start(name, flags, pin):
    port = free_port()
    process = subprocess.Popen((["taskset", "-c", "0"] if pin else [])
                               + [os.path.join(BIN, "nupmpc-server"), f"--address=127.0.0.1:{port}", "--log_level=warn"]
                               + flags)
    return {"name": name, "process": process, "port": port}


def wait_ready(server, client_flags):
    for _ in range(100):
        if subprocess.run([os.path.join(BIN, "nupmpc"), f"--server=127.0.0.1:{server['port']}", "--deadline_ms=1000",
                           "info"] + client_flags, capture_output=True).returncode == 0:
            return
        time.sleep(0.1)
    sys.exit(f"{server['name']}: the server did not come up")


def scrape_forever(port, stop):
    while not stop.is_set():
        try:
            urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=2).read()
        except OSError:
            pass
        stop.wait(1.0)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--duration_s", type=float, default=3.0)
    parser.add_argument("--levels", default="1,8")
    parser.add_argument("--pin", action="store_true")
    parser.add_argument("--instance", default=os.path.join(ROOT, "benchmarks", "masses_N30.json"))
    args = parser.parse_args()
    levels = [int(c) for c in args.levels.split(",")]

    with tempfile.TemporaryDirectory() as directory:
        cert, key = make_certificate(directory)
        tokens = os.path.join(directory, "tokens")
        with open(tokens, "w") as f:
            f.write(f"{TOKEN} loadtest\n")
        token_file = os.path.join(directory, "token")
        with open(token_file, "w") as f:
            f.write(TOKEN + "\n")
        metrics_port = free_port()
        tls = [f"--tls_cert_file={cert}", f"--tls_key_file={key}"]
        servers = [start("plain", [], args.pin),
                   start("metrics", [f"--metrics_address=127.0.0.1:{metrics_port}"], args.pin),
                   start("tls", tls, args.pin),
                   start("tls+token", tls + [f"--auth_tokens_file={tokens}"], args.pin)]
        client_flags = {"plain": [], "metrics": [], "tls": [f"--tls_ca_file={cert}"],
                        "tls+token": [f"--tls_ca_file={cert}", f"--token_file={token_file}"]}
        stop = threading.Event()
        scraper = threading.Thread(target=scrape_forever, args=(metrics_port, stop), daemon=True)
        try:
            for server in servers:
                wait_ready(server, client_flags[server["name"]])
            scraper.start()
            results = {}  # (server, level) -> [(solves/s, p50 ms, p99 ms)]
            for round_index in range(args.rounds):
                for level in levels:
                    shift = round_index % len(servers)
                    for server in servers[shift:] + servers[:shift]:
                        out = subprocess.run(
                            (["taskset", "-c", "1"] if args.pin else []) + [os.path.join(BIN, "nupmpc-loadtest"), f"--server=127.0.0.1:{server['port']}",
                             f"--instance={args.instance}", f"--concurrency={level}", "--echo=false", "--json",
                             "--progress=off", f"--duration_s={args.duration_s}", "--transport_calls=200",
                             "--baseline_rounds=2"] + client_flags[server["name"]],
                            check=True, capture_output=True, text=True).stdout
                        row = json.loads(out)["levels"][0]
                        results.setdefault((server["name"], level), []).append(
                            (row["solves_per_s"], row["p50_ms"], row["p99_ms"]))
                print(f"round {round_index + 1}/{args.rounds} done", file=sys.stderr)
        finally:
            stop.set()
            for server in servers:
                server["process"].terminate()
            for server in servers:
                server["process"].wait()

    placement = ("servers on CPU 0, load generator on CPU 1" if args.pin
                 else f"server and load generator share the {os.cpu_count()} CPUs")
    print(f"masses_N30 closed loop, {args.rounds} rounds of {args.duration_s:g} s per server and level, "
          f"interleaved; medians of the rounds ({placement}); range: min-max solves/s over the rounds")
    print(f"{'C':>3} {'server':<10} {'solves/s':>9} {'range':>11} {'vs plain':>9} {'p50 ms':>8} {'vs plain':>9} "
          f"{'p99 ms':>8}")
    for level in levels:
        base = [statistics.median(v) for v in zip(*results[("plain", level)])]
        for server in servers:
            med = [statistics.median(v) for v in zip(*results[(server["name"], level)])]
            rates = [r[0] for r in results[(server["name"], level)]]
            spread = f"{min(rates):.0f}-{max(rates):.0f}"
            print(f"{level:>3} {server['name']:<10} {med[0]:>9.0f} {spread:>11} {med[0] / base[0]:>9.3f} {med[1]:>8.3f} "
                  f"{med[1] / base[1]:>9.3f} {med[2]:>8.3f}")


if __name__ == "__main__":
    main()
