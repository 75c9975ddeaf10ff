"""What the soak (soak.py) and the fault scenarios (faults.py) share: the import path of
a checkout, the real nupmpc-server binary as a child process whose memory and file
descriptors are read from /proc, the workloads (the masses_N30 benchmark and its recorded
states, a keep-out and a GP-MPC problem) and percentiles."""

import os
import pathlib
import re
import sys
import urllib.request

REPO = pathlib.Path(__file__).resolve().parents[2]
for _path in (str(REPO / "client" / "python"), os.environ.get("NUPMPC_PYTHON_STUBS", str(REPO / "build" / "python"))):
    if _path not in sys.path:
        sys.path.insert(0, _path)

import numpy as np  # noqa: E402

import nupmpc  # noqa: E402
from nupmpc._proto import pb  # noqa: E402
from nupmpc.local_server import LocalServer, default_binary  # noqa: E402

SERVER_BINARY = default_binary()
BENCHMARKS = pathlib.Path(os.environ.get("NUPMPC_BENCHMARK_DIR", str(REPO / "benchmarks")))
MASSES = BENCHMARKS / "masses_N30.json"


class HarnessError(RuntimeError):
    """The set-up failed (a tool exited with an error): a failed run, never a skipped one.
    A server that cannot start raises nupmpc.local_server.LocalServerError, no less fatal."""


class Server(LocalServer):
    """nupmpc-server on a loopback port with its metrics endpoint, started at once, and the
    figures the soak reads from it; start() after kill() brings a new process up on the
    same ports (what a supervisor does after a crash)."""

    def __init__(self, *flags, cpus=None):
        """cpus: the CPUs the server may run on (None: any)."""
        super().__init__(SERVER_BINARY, *flags, metrics=True, cpus=cpus)
        try:
            self.start()
        except BaseException:
            self.stop()
            raise

    def rss_bytes(self):
        """VmRSS from /proc: the kernel's figure, independent of the server's own report."""
        with open(f"/proc/{self.pid}/status") as f:
            return int(re.search(r"^VmRSS:\s+(\d+) kB", f.read(), re.M).group(1)) * 1024

    def open_fds(self):
        return len(os.listdir(f"/proc/{self.pid}/fd"))

    def threads(self):
        return len(os.listdir(f"/proc/{self.pid}/task"))

    def metrics(self):
        """/metrics as {'name{labels}': value}."""
        text = urllib.request.urlopen(f"{self.metrics_url}/metrics", timeout=5).read().decode()
        values = {}
        for line in text.splitlines():
            if line and not line.startswith("#"):
                name, _, value = line.rpartition(" ")
                values[name] = float(value)
        return values

    def metric_sum(self, prefix, **labels):
        """The sum of every series of metric `prefix` whose labels include `labels`."""
        total = 0.0
        for name, value in self.metrics().items():
            base, _, rest = name.partition("{")
            if base == prefix and all(f'{k}="{v}"' in rest for k, v in labels.items()):
                total += value
        return total


def masses():
    """The masses_N30 benchmark (12 states, 3 inputs, 12 outputs) and its recorded states."""
    instance = nupmpc.load_instance(MASSES)
    return instance.spec, np.asarray(instance.closed_loop_states)


def keep_out_problem():
    """A point mass in the plane around a disc and a rotated rectangle (the obstacle
    example), and its plant x[t+1] = A x[t] + B u[t]."""
    dt = 0.1
    A = np.eye(4)
    A[0, 2] = A[1, 3] = dt
    B = np.array([[dt * dt / 2, 0], [0, dt * dt / 2], [dt, 0], [0, dt]])
    goal = np.array([4.0, 3.0])
    regions = [nupmpc.Ellipse(centre=(1.5, 1.0), a=0.6), nupmpc.Rectangle(centre=(2.6, 2.5), a=0.4, b=0.25, rotation=0.5)]
    problem = (nupmpc.Problem(A, B, np.eye(2, 4), horizon=20, x0=[0, 0, 0, 0])
               .output_weight(1.0, reference=goal).input_weight(0.05).input_box(-3, 3)
               .terminal_cost(np.eye(4) * 50, target=[*goal, 0, 0]).keep_out(0, 1, regions))
    return problem, lambda x, u: A @ x + B @ u


def gp_problem(seed):
    """GP-MPC on a logged tank-like plant (the GP example), kernel given (no fit at creation)."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1, 1, 60)
    y = np.zeros(60)
    for k in range(1, 60):
        y[k] = 0.9 * y[k - 1] + 0.4 * np.tanh(u[k]) + 0.02 * rng.standard_normal()
    kernel = pb.GpKernel(length_scales=[1.0, 1.0], signal_variance=0.3, noise_variance=4e-4)
    return nupmpc.GpProblem(y, u, output_lags=1, input_lags=0, horizon=8, output_weight=10.0,
                            input_change_weight=0.1, input_bounds=(-1, 1), rate_bounds=(-0.3, 0.3),
                            sigma_multiple=2.0, reference=0.0, kernel=kernel)


def percentile(values, q):
    if len(values) == 0:
        return float("nan")
    return float(np.percentile(np.asarray(values), q))
