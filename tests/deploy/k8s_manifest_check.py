#!/usr/bin/python3
"""Checks the Kubernetes manifests of deploy/k8s/ without a cluster.

    k8s_manifest_check.py SOURCE_DIR             check SOURCE_DIR/deploy/k8s/
    k8s_manifest_check.py --selftest SOURCE_DIR  plant mistakes in a copy, see each one caught

Runs with Debian 12's own interpreter (/usr/bin/python3) and packages: python3-yaml,
python3-kubernetes and yamllint. Every YAML document under deploy/k8s/ goes through:

1. PyYAML: it parses.
2. yamllint, with tests/deploy/yamllint.yaml: every problem fails.
3. A schema check with the kubernetes client's models: apiVersion/kind name a model class,
   the client's ApiClient deserializes the document into it, and the input is walked
   alongside the resulting object. A field the model does not know is dropped by the
   deserializer (and so missing from sanitize_for_serialization's output): that is a typo or
   a field of another kind, reported with the closest known names. A value the deserializer
   had to convert (2 where the schema wants the string "2", "yes" where it wants a boolean)
   is reported too: the API server would refuse it. Missing required fields fail in the
   models' constructors.
4. Cross-checks between the files, each a way a deployment goes wrong that the schema cannot
   see: probes, grace period against the drain, selectors, the HPA's target, the resources
   against the server's thread and memory settings, every NUPMPC_* key against the server's
   real flags (parsed out of server/server_flags.cc), the balancer's configuration (HTTP/2
   frames of its health check, its server slots against the HPA, `haproxy -c` when haproxy
   is installed, with made-up certificates in place of the Secrets), and the TLS wiring
   (k8s_tls_check.py: Secrets made by make-secrets.sh, the files the flags and the balancer
   name mounted, probes that work with TLS, the caller's subject header).

Exit status 1 with one line per finding, naming file, document and field.
"""

import difflib
import json
import os
import re
import shutil
import sys
import tempfile

try:
    import yaml
    import kubernetes.client
    import kubernetes.client.models as k8s_models
    from yamllint import linter as yamllint_linter
    from yamllint.config import YamlLintConfig
except ImportError as error:
    sys.exit(f"k8s_manifest_check.py: {error}: needs the Debian packages python3-yaml, python3-kubernetes and "
             f"yamllint, and Debian's interpreter /usr/bin/python3 (this is {sys.executable})")

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import k8s_tls_check as k8s_tls  # noqa: E402 (beside this file)
LINT_CONFIG = os.path.join(HERE, "yamllint.yaml")

# The model class of each apiVersion/kind the manifests may use.
MODELS = {
    ("v1", "ConfigMap"): "V1ConfigMap",
    ("v1", "Service"): "V1Service",
    ("apps/v1", "Deployment"): "V1Deployment",
    ("policy/v1", "PodDisruptionBudget"): "V1PodDisruptionBudget",
    ("autoscaling/v2", "HorizontalPodAutoscaler"): "V2HorizontalPodAutoscaler",
}

# Server flags the manifests may set before server/server_flags.cc declares them: each is added
# by work under way (a manifest may land before the server change that adds its flag).
# Harmless once the flag exists.
PENDING_FLAGS = {}  # flags a manifest may name before the server has them: {flag: why}

# Seconds the pod needs beyond drain delay + grace: closing the listener and the streams left,
# and exiting, before the kubelet's SIGKILL.
MIN_TERMINATION_MARGIN_S = 5

SERVER_IMAGE = "nupmpc"
BALANCER_IMAGE = "nupmpc-haproxy"
SESSION_HEADER = "x-nupmpc-session"


# ---------------------------------------------------------------------------------------------
# The kubernetes client's models as the schema.

def backport_newer_fields():
    """Teaches an older client's models the two newer API parts these manifests use.

    Debian 12's python3-kubernetes is 22.6, the Kubernetes 1.22 API. It predates
    - gRPC probes (Kubernetes 1.24): V1Probe gets `grpc`, a V1GRPCAction {port: int, required;
      service: string}, as the API defines it;
    - autoscaling/v2 (Kubernetes 1.23): validated with the autoscaling/v2beta2 models, whose
      schema v2 took over unchanged.
    With a client that has them, nothing is patched. Returns what was added, for the report.
    """
    global _BACKPORTED
    if _BACKPORTED is not None:
        return _BACKPORTED
    added = []
    if not hasattr(k8s_models, "V1GRPCAction"):
        class V1GRPCAction:
            openapi_types = {"port": "int", "service": "str"}
            attribute_map = {"port": "port", "service": "service"}

            def __init__(self, port=None, service=None, local_vars_configuration=None):
                if port is None:
                    raise ValueError("Invalid value for `port`, must not be `None`")
                self.port = port
                self.service = service

        class V1Probe(k8s_models.V1Probe):
            openapi_types = dict(k8s_models.V1Probe.openapi_types, grpc="V1GRPCAction")
            attribute_map = dict(k8s_models.V1Probe.attribute_map, grpc="grpc")

            def __init__(self, grpc=None, **kwargs):
                super().__init__(**kwargs)
                self.grpc = grpc

        # The deserializer looks nested types up by name in this module.
        k8s_models.V1GRPCAction = V1GRPCAction
        k8s_models.V1Probe = V1Probe
        added.append("V1Probe.grpc")
    if not hasattr(k8s_models, "V2HorizontalPodAutoscaler"):
        MODELS[("autoscaling/v2", "HorizontalPodAutoscaler")] = "V2beta2HorizontalPodAutoscaler"
        added.append("autoscaling/v2 as v2beta2")
    _BACKPORTED = added
    return added


_BACKPORTED = None


class _Response:
    """What ApiClient.deserialize reads from an HTTP response: the body as .data."""

    def __init__(self, document):
        # default=str: a YAML date or timestamp becomes a string here and is then reported
        # as a converted value, which it is for the API server.
        self.data = json.dumps(document, default=str)


def _is_quantity_path(path):
    """Quantities (cpu: 2, memory: 4Gi) are strings in the models but numbers are fine in YAML."""
    return re.search(r"\.(limits|requests)\.[^.]+$|\.(averageValue|value)$", path) is not None


def schema_findings(document, model_name, where):
    """Deserializes document into model_name and reports what did not survive the trip."""
    api = kubernetes.client.ApiClient()
    try:
        obj = api.deserialize(_Response(document), model_name)
    except (ValueError, TypeError) as error:
        return [f"{where}: {error}"]
    findings = []

    def walk(value, model_value, path):
        if value is None:
            return  # null is "not set" for the API server, and for the deserializer
        if hasattr(model_value, "openapi_types"):
            if not isinstance(value, dict):
                findings.append(f"{where} {path}: a mapping expected, got {value!r}")
                return
            json_to_attr = {json_name: attr for attr, json_name in model_value.attribute_map.items()}
            for key, sub in value.items():
                if key not in json_to_attr:
                    known = sorted(json_to_attr)
                    close = difflib.get_close_matches(str(key), known, n=2)
                    hint = f"did you mean {' or '.join(close)}?" if close else f"known: {', '.join(known)}"
                    findings.append(f"{where} {join(path, key)}: unknown field of {type(model_value).__name__} "
                                    f"(dropped by the schema; {hint})")
                    continue
                walk(sub, getattr(model_value, json_to_attr[key]), join(path, key))
        elif isinstance(model_value, dict):
            if not isinstance(value, dict):
                findings.append(f"{where} {path}: a mapping expected, got {value!r}")
                return
            for key, sub in value.items():
                walk(sub, model_value.get(key), join(path, key))
        elif isinstance(model_value, list):
            if not isinstance(value, list):
                findings.append(f"{where} {path}: a list expected, got {value!r}")
                return
            for i, (sub, model_sub) in enumerate(zip(value, model_value)):
                walk(sub, model_sub, f"{path}[{i}]")
        else:
            # A leaf: what the deserializer made of it is what the API would see.
            back = api.sanitize_for_serialization(model_value)
            same = type(value) is type(back) and value == back
            if not same and not (isinstance(value, (int, float)) and not isinstance(value, bool)
                                 and isinstance(back, str) and _is_quantity_path(path)):
                findings.append(f"{where} {path}: {value!r} ({type(value).__name__}) does not fit the schema "
                                f"(the client made it {back!r}); quote it or fix its type")

    walk(document, obj, "")
    return findings


def join(path, key):
    return f"{path}.{key}" if path else str(key)


def commented_variants(text):
    """Alternatives kept as comments, e.g. hpa.yaml's custom-metric `metrics`, to check too.

    A comment line `# <field>:` directly under a top-level key, followed by more deeply
    indented comment lines, is uncommented and yields (field, top-level key, its value); the
    check puts it in place of the document's own and validates the result. Only the first
    document of a file is searched (hpa.yaml has one).
    """
    lines = text.split("\n---", 1)[0].splitlines()
    for i, line in enumerate(lines):
        m = re.fullmatch(r"(  )# (\w+):", line)
        if not m:
            continue
        parent = next((re.match(r"(\w+):", p).group(1) for p in reversed(lines[:i]) if re.match(r"\w+:", p)), None)
        body = []
        for follow in lines[i + 1:]:
            if not follow.startswith(m.group(1) + "#   "):
                break
            body.append(follow[len(m.group(1)) + 2:])
        if parent and body:
            yield m.group(2), parent, yaml.safe_load("\n".join(body))


# ---------------------------------------------------------------------------------------------
# The server's flags, from its sources.

# The flags ParseServerFlags reads from the environment: `for (const char* name : {"address", ...})`.
ENV_LIST = re.compile(r"for \(const char\* name :\s*\{(.*?)\}\)", re.S)


def server_flags(source_dir):
    """Returns (flags settable from the environment, flags declared only, pending flags used)."""
    path = os.path.join(source_dir, "server", "server_flags.cc")
    with open(path, encoding="utf-8") as f:
        text = f.read()
    declared = set(re.findall(r"ABSL_FLAG\(\s*[\w:<>]+\s*,\s*(\w+)\s*,", text))
    # ParseServerFlags applies NUPMPC_<FLAG> for the flags in one list; a declared flag that is
    # missing there would silently ignore its environment variable.
    listed = ENV_LIST.search(text)
    from_env = set(re.findall(r'"(\w+)"', listed.group(1))) & declared if listed else set(declared)
    return from_env, declared


# ---------------------------------------------------------------------------------------------
# Small readers.

def quantity(value):
    """A Kubernetes quantity ("2", 2, "500m", "4Gi") as a number of units (cores, bytes)."""
    suffixes = {"": 1, "m": 1e-3, "k": 1e3, "M": 1e6, "G": 1e9, "T": 1e12,
                "Ki": 2**10, "Mi": 2**20, "Gi": 2**30, "Ti": 2**40}
    m = re.fullmatch(r"([0-9]+(?:\.[0-9]+)?)([a-zA-Z]*)", str(value).strip())
    if not m or m.group(2) not in suffixes:
        raise ValueError(f"not a quantity: {value!r}")
    return float(m.group(1)) * suffixes[m.group(2)]


def haproxy_duration_s(text):
    m = re.fullmatch(r"([0-9]+)(us|ms|s|m|h|d)?", text)
    if not m:
        raise ValueError(f"not an HAProxy duration: {text!r}")
    return int(m.group(1)) * {"us": 1e-6, "ms": 1e-3, None: 1e-3, "s": 1, "m": 60, "h": 3600, "d": 86400}[m.group(2)]


HAPROXY_SECTIONS = {"global", "defaults", "frontend", "backend", "listen", "resolvers", "peers", "userlist",
                    "program", "http-errors", "ring", "mailers", "cache"}


def haproxy_sections(cfg):
    """[(keyword, name, [lines without comments])] of an HAProxy configuration."""
    sections = []
    for raw in cfg.splitlines():
        line = raw.split("#", 1)[0].strip()  # no '#' inside quotes in our configuration
        if not line:
            continue
        words = line.split()
        if words[0] in HAPROXY_SECTIONS:
            sections.append((words[0], words[1] if len(words) > 1 else "", []))
        elif sections:
            sections[-1][2].append(line)
    return sections


def h2_health_check_findings(lines, where):
    """The raw HTTP/2 frames of the balancer's tcp-check: a well-formed Health/Check call."""
    findings = []
    sends = [line.split()[2] for line in lines if line.startswith("tcp-check send-binary ")]
    expects = [" ".join(line.split()[2:]) for line in lines if line.startswith("tcp-check expect ")]
    if not sends:
        return [f"{where}: no `tcp-check send-binary`: the balancer must check grpc.health.v1"]
    try:
        data = bytes.fromhex("".join(sends))
    except ValueError as error:
        return [f"{where}: tcp-check send-binary: {error}"]
    preface = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n"
    if not data.startswith(preface):
        return [f"{where}: the health check does not open with the HTTP/2 client preface"]
    rest = data[len(preface):]
    frames = []
    while rest:
        if len(rest) < 9:
            findings.append(f"{where}: health check: {len(rest)} stray bytes after the last frame")
            break
        length, ftype, flags = int.from_bytes(rest[0:3], "big"), rest[3], rest[4]
        stream = int.from_bytes(rest[5:9], "big") & 0x7FFFFFFF
        payload = rest[9:9 + length]
        if len(payload) != length:
            findings.append(f"{where}: health check: a frame of type {ftype} says {length} bytes, "
                            f"{len(payload)} follow")
            break
        frames.append((ftype, flags, stream, payload))
        rest = rest[9 + length:]
    shape = [(t, s) for t, _, s, _ in frames]
    if shape != [(4, 0), (1, 1), (0, 1)]:
        findings.append(f"{where}: health check frames (type, stream) are {shape}, expected SETTINGS on 0, "
                        f"HEADERS and DATA on stream 1")
        return findings
    _, headers_flags, _, headers = frames[1]
    _, data_flags, _, body = frames[2]
    path = b"/grpc.health.v1.Health/Check"
    if not headers_flags & 0x4 or bytes([len(path)]) + path not in headers:
        findings.append(f"{where}: health check HEADERS: END_HEADERS and the :path literal "
                        f"{path.decode()} (with its length byte) expected")
    if not data_flags & 0x1 or len(body) < 5 or body[0] != 0 or int.from_bytes(body[1:5], "big") != len(body) - 5:
        findings.append(f"{where}: health check DATA: END_STREAM and one uncompressed gRPC message expected")
    # First wait for an answer, SERVING or NOT_SERVING; then decide on it at once (min-recv 0),
    # rather than wait out `timeout check` for a SERVING that will not come.
    if expects != ["rbinary 0000000002080[12]", "min-recv 0 binary 00000000020801"]:
        findings.append(f"{where}: health check: expected `tcp-check expect rbinary 0000000002080[12]` then "
                        f"`tcp-check expect min-recv 0 binary 00000000020801` (HealthCheckResponse status "
                        f"SERVING), found {expects}")
    return findings


# ---------------------------------------------------------------------------------------------
# The check.

class Manifests:
    """The documents of deploy/k8s/, by kind, each with where it came from."""

    def __init__(self):
        self.docs = []  # (where, document)

    def of_kind(self, kind):
        return [(w, d) for w, d in self.docs if d.get("kind") == kind]

    def named(self, kind, name):
        for where, doc in self.of_kind(kind):
            if doc.get("metadata", {}).get("name") == name:
                return where, doc
        return None, None


def containers_of(deployment):
    return deployment.get("spec", {}).get("template", {}).get("spec", {}).get("containers", []) or []


def image_name(container):
    """nupmpc for nupmpc:latest or registry.example/nupmpc:1.2."""
    return str(container.get("image", "")).rsplit("/", 1)[-1].split(":", 1)[0].split("@", 1)[0]


def pod_labels(deployment):
    return deployment.get("spec", {}).get("template", {}).get("metadata", {}).get("labels", {}) or {}


def selects(selector, labels):
    return bool(selector) and all(labels.get(k) == v for k, v in selector.items())


def check(source_dir):
    """Returns (findings, notes, number of documents)."""
    k8s_dir = os.path.join(source_dir, "deploy", "k8s")
    findings, notes = [], []
    added = backport_newer_fields()
    if added:
        notes.append(f"the packaged kubernetes client ({kubernetes.__version__}) predates {', '.join(added)}: "
                     f"checked with the backported definitions")
    files = sorted(f for f in os.listdir(k8s_dir) if f.endswith((".yaml", ".yml")))
    if not files:
        return [f"{k8s_dir}: no YAML files"], notes, 0
    lint_config = YamlLintConfig(file=LINT_CONFIG)
    manifests = Manifests()
    for name in files:
        path = os.path.join(k8s_dir, name)
        with open(path, encoding="utf-8") as f:
            text = f.read()
        for problem in yamllint_linter.run(text, lint_config, path):
            findings.append(f"{name}:{problem.line}:{problem.column}: yamllint {problem.level}: {problem.desc}"
                            f" ({problem.rule})")
        try:
            documents = [d for d in yaml.safe_load_all(text) if d is not None]
        except yaml.YAMLError as error:
            findings.append(f"{name}: does not parse: {error}")
            continue
        for i, doc in enumerate(documents, 1):
            if not isinstance(doc, dict):
                findings.append(f"{name} document {i}: not a mapping")
                continue
            kind, api_version = doc.get("kind"), doc.get("apiVersion")
            where = f"{name} document {i} ({kind}/{doc.get('metadata', {}).get('name')})"
            model = MODELS.get((api_version, kind))
            if model is None:
                findings.append(f"{where}: apiVersion {api_version!r} kind {kind!r} has no schema here "
                                f"(known: {', '.join(f'{a} {k}' for a, k in MODELS)})")
                continue
            findings += schema_findings(doc, model, where)
            manifests.docs.append((where, doc))
            if i == 1:
                for key, parent, block in commented_variants(text):
                    variant = dict(doc, **{parent: dict(doc.get(parent) or {}, **{key: block})})
                    findings += schema_findings(variant, model, f"{where} (commented variant)")
    try:
        findings += cross_findings(manifests, source_dir, notes)
    except (KeyError, IndexError, TypeError, AttributeError, StopIteration) as error:
        # A field the cross-checks rely on is missing or malformed; the schema check above has
        # usually said which already.
        findings.append(f"deploy/k8s: the cross-checks stopped at a missing or malformed field: "
                        f"{type(error).__name__} {error}")
    return findings, notes, len(manifests.docs)


def cross_findings(m, source_dir, notes):
    findings = []

    def need(condition, message):
        if not condition:
            findings.append(message)
        return condition

    deployments = m.of_kind("Deployment")
    servers = [(w, d) for w, d in deployments if any(image_name(c) == SERVER_IMAGE for c in containers_of(d))]
    balancers = [(w, d) for w, d in deployments if any(image_name(c) == BALANCER_IMAGE for c in containers_of(d))]
    if not need(len(servers) == 1, f"deploy/k8s: {len(servers)} Deployments run the image {SERVER_IMAGE}, expected 1"):
        return findings
    where, server = servers[0]
    server_name = server["metadata"]["name"]
    pod_spec = server["spec"]["template"]["spec"]
    container = next(c for c in containers_of(server) if image_name(c) == SERVER_IMAGE)

    # Every Deployment's own selector picks its pods.
    for w, d in deployments:
        need(selects(d.get("spec", {}).get("selector", {}).get("matchLabels"), pod_labels(d)),
             f"{w} spec.selector.matchLabels: does not match spec.template.metadata.labels")

    # The configuration: every key a real server flag read from the environment.
    config, cm_where = {}, where
    refs = [e["configMapRef"]["name"] for e in container.get("envFrom", []) or [] if "configMapRef" in e]
    if need(refs, f"{where} containers[{container.get('name')}].envFrom: no configMapRef (the NUPMPC_* settings)"):
        for ref in refs:
            cm_where, cm = m.named("ConfigMap", ref)
            if need(cm is not None, f"{where} envFrom: ConfigMap {ref!r} is not among the manifests"):
                config.update(cm.get("data", {}) or {})
                from_env, declared = server_flags(source_dir)
                for key in cm.get("data", {}) or {}:
                    flag = key[len("NUPMPC_"):].lower() if key.startswith("NUPMPC_") else None
                    if flag is None:
                        findings.append(f"{cm_where} data.{key}: not a NUPMPC_<FLAG> setting")
                    elif flag in from_env:
                        pass
                    elif flag in declared:
                        findings.append(f"{cm_where} data.{key}: --{flag} is declared in server/server_flags.cc "
                                        f"but ParseServerFlags does not read it from the environment")
                    elif flag in PENDING_FLAGS:
                        notes.append(f"{cm_where} data.{key}: --{flag} is not in server/server_flags.cc yet "
                                     f"({PENDING_FLAGS[flag]}); accepted as pending")
                    else:
                        close = difflib.get_close_matches(flag, sorted(from_env), n=1)
                        hint = f" (did you mean NUPMPC_{close[0].upper()}?)" if close else ""
                        findings.append(f"{cm_where} data.{key}: no server flag --{flag} in server/server_flags.cc"
                                        f"{hint}")

    def setting(key):
        if not need(key in config, f"{where}: the ConfigMap must set {key} (the manifests' timing depends on it)"):
            return None
        try:
            return float(config[key])
        except (TypeError, ValueError):
            findings.append(f"{where}: {key}={config[key]!r} is not a number")
            return None

    # Grace period: the pod's SIGKILL deadline covers the server's drain.
    drain, grace = setting("NUPMPC_DRAIN_DELAY_S"), setting("NUPMPC_GRACE_PERIOD_S")
    tgps = pod_spec.get("terminationGracePeriodSeconds")
    if need(tgps is not None, f"{where} spec.template.spec.terminationGracePeriodSeconds: not set "
                              f"(the default 30 s would be an accident)") and drain is not None and grace is not None:
        need(tgps >= drain + grace + MIN_TERMINATION_MARGIN_S,
             f"{where} spec.template.spec.terminationGracePeriodSeconds: {tgps} s < NUPMPC_DRAIN_DELAY_S {drain:g} "
             f"+ NUPMPC_GRACE_PERIOD_S {grace:g} + {MIN_TERMINATION_MARGIN_S} s margin: the kubelet would kill "
             f"in-flight solves")

    # Probes (native gRPC, or HTTP on the metrics port with TLS), TLS files, Secrets.
    cname = f"containers[{container.get('name')}]"
    findings += k8s_tls.server_findings(where, server, container, config, cm_where)
    findings += k8s_tls.secret_findings(os.path.join(source_dir, "deploy", "k8s"), deployments)
    liveness = container.get("livenessProbe") or {}
    window = liveness.get("periodSeconds", 10) * liveness.get("failureThreshold", 3)
    if drain is not None and liveness:
        need(window > drain, f"{where} {cname}.livenessProbe: fails after {window} s of NOT_SERVING, not longer than "
                             f"NUPMPC_DRAIN_DELAY_S {drain:g}: a drain could look like a hung server")

    # Resources: two whole CPUs, the worker pool and the memory budget to match.
    resources = container.get("resources", {}) or {}
    limits, requests = resources.get("limits", {}) or {}, resources.get("requests", {}) or {}
    try:
        need("cpu" in limits and quantity(limits["cpu"]) == 2,
             f"{where} {cname}.resources.limits.cpu: {limits.get('cpu')!r}, the server is sized for \"2\"")
        need("cpu" in requests, f"{where} {cname}.resources.requests.cpu: missing (the HPA's utilisation is of it)")
        if "NUPMPC_THREADS" in config and "cpu" in limits:
            need(float(config["NUPMPC_THREADS"]) == quantity(limits["cpu"]),
                 f"{where}: NUPMPC_THREADS {config['NUPMPC_THREADS']} differs from resources.limits.cpu "
                 f"{limits['cpu']}: one solver worker per CPU")
        budget = float(config.get("NUPMPC_MEMORY_BUDGET_MB", 0) or 0)
        if need("memory" in limits, f"{where} {cname}.resources.limits.memory: missing") and budget > 0:
            limit_mb = quantity(limits["memory"]) / 2**20
            need(budget <= 0.9 * limit_mb,
                 f"{where}: NUPMPC_MEMORY_BUDGET_MB {budget:g} is not below resources.limits.memory "
                 f"({limit_mb:g} MiB) with 10% left for the process: the OOM killer would act before the budget")
    except ValueError as error:
        findings.append(f"{where} {cname}.resources: {error}")

    # Services' environment variables share the server's prefix: keep them out.
    collide = [d["metadata"]["name"] for _, d in m.of_kind("Service")
               if d["metadata"]["name"].upper().replace("-", "_").startswith("NUPMPC")]
    if collide:
        need(pod_spec.get("enableServiceLinks") is False,
             f"{where} spec.template.spec.enableServiceLinks: must be false: the Services {collide} would put "
             f"NUPMPC_*_SERVICE_HOST/_PORT variables into the server's NUPMPC_<FLAG> environment")

    # Services select the pods of exactly one Deployment, on a port those pods have.
    headless = []
    for w, svc in m.of_kind("Service"):
        spec = svc.get("spec", {})
        selector = spec.get("selector") or {}
        targets = [(dw, d) for dw, d in deployments if selects(selector, pod_labels(d))]
        if not need(len(targets) == 1, f"{w} spec.selector: {selector} matches the pods of {len(targets)} "
                                       f"Deployments, expected exactly 1"):
            continue
        target = targets[0][1]
        target_ports = {p.get("containerPort") for c in containers_of(target) for p in c.get("ports", []) or []}
        target_names = {p.get("name") for c in containers_of(target) for p in c.get("ports", []) or []}
        for i, port in enumerate(spec.get("ports", []) or []):
            tp = port.get("targetPort", port.get("port"))
            need(tp in target_ports or tp in target_names,
                 f"{w} spec.ports[{i}].targetPort: {tp!r} is not a container port of Deployment "
                 f"{target['metadata']['name']}")
        if spec.get("clusterIP") == "None" and target is server:
            headless.append(svc)
    need(headless, "deploy/k8s: no headless Service (clusterIP None) selects the server pods: the balancer "
                   "resolves the replicas through one")

    # The PodDisruptionBudget guards the server replicas.
    hpas = m.of_kind("HorizontalPodAutoscaler")
    min_replicas = hpas[0][1].get("spec", {}).get("minReplicas", 1) if hpas else server["spec"].get("replicas", 1)
    for w, pdb in m.of_kind("PodDisruptionBudget"):
        need(selects(pdb.get("spec", {}).get("selector", {}).get("matchLabels"), pod_labels(server)),
             f"{w} spec.selector.matchLabels: does not select Deployment {server_name}'s pods")
        min_available = pdb.get("spec", {}).get("minAvailable")
        if isinstance(min_available, int):
            need(min_available < min_replicas, f"{w} spec.minAvailable: {min_available} leaves no replica evictable "
                                               f"at {min_replicas} replicas: node drains would block")
    need(m.of_kind("PodDisruptionBudget"), "deploy/k8s: no PodDisruptionBudget")

    # The HPA scales the server Deployment, within the balancer's slots.
    slots = None
    for w, hpa in hpas:
        spec = hpa.get("spec", {})
        ref = spec.get("scaleTargetRef", {})
        need((ref.get("apiVersion"), ref.get("kind"), ref.get("name")) == ("apps/v1", "Deployment", server_name),
             f"{w} spec.scaleTargetRef: {ref.get('apiVersion')} {ref.get('kind')} {ref.get('name')}, expected "
             f"apps/v1 Deployment {server_name}")
        need(spec.get("minReplicas", 1) <= spec.get("maxReplicas", 0),
             f"{w} spec: minReplicas {spec.get('minReplicas')} > maxReplicas {spec.get('maxReplicas')}")
    need(hpas, "deploy/k8s: no HorizontalPodAutoscaler")

    # The balancer.
    if need(len(balancers) == 1, f"deploy/k8s: {len(balancers)} Deployments run the image {BALANCER_IMAGE}, "
                                 f"expected 1"):
        slots = balancer_findings(m, balancers[0], headless, drain, config, findings, notes)
    if slots is not None:
        for w, hpa in hpas:
            need(hpa["spec"].get("maxReplicas", 0) <= slots,
                 f"{w} spec.maxReplicas: {hpa['spec'].get('maxReplicas')} exceeds the balancer's {slots} server "
                 f"slots (server-template): the extra replicas would get no traffic")
    return findings


def balancer_findings(m, balancer, headless, drain, server_config, findings, notes):
    """The HAProxy Deployment and its configuration. Returns the number of server slots."""
    where, deployment = balancer

    def need(condition, message):
        if not condition:
            findings.append(message)
        return condition

    container = next(c for c in containers_of(deployment) if image_name(c) == BALANCER_IMAGE)
    pod_volumes = {v.get("name"): v for v in deployment["spec"]["template"]["spec"].get("volumes", []) or []}
    maps = [pod_volumes[v["name"]]["configMap"]["name"] for v in container.get("volumeMounts", []) or []
            if "configMap" in pod_volumes.get(v.get("name"), {})]
    cfg, cfg_where = None, None
    for name in maps:
        w, cm = m.named("ConfigMap", name)
        if need(cm is not None, f"{where}: mounts ConfigMap {name!r}, which is not among the manifests"):
            if "haproxy.cfg" in (cm.get("data") or {}):
                cfg, cfg_where = cm["data"]["haproxy.cfg"], f"{w} data.haproxy.cfg"
    if not need(cfg is not None, f"{where}: mounts no ConfigMap with a haproxy.cfg"):
        return None
    sections = haproxy_sections(cfg)

    # Environment variables the configuration uses: an unset one expands to nothing.
    env = {e.get("name"): e for e in container.get("env", []) or []}
    for var in sorted(set(re.findall(r"\$\{(\w+)\}", cfg))):
        need(var in env, f"{cfg_where}: uses ${{{var}}}, which the container {container.get('name')!r} does not set")

    def section(keyword, name):
        return next((lines for k, n, lines in sections if k == keyword and n == name), None)

    backends = {n: lines for k, n, lines in sections if k == "backend"}
    frontends = [lines for k, n, lines in sections if k == "frontend"]
    routing = [line for lines in frontends for line in lines if line.startswith("use_backend")]
    pinned = [name for name, lines in backends.items() if f"balance hdr({SESSION_HEADER})" in lines]
    if need(len(pinned) == 1,
            f"{cfg_where}: expected one backend with `balance hdr({SESSION_HEADER})`, found {pinned}"):
        lines = backends[pinned[0]]
        need("hash-type consistent" in lines, f"{cfg_where} backend {pinned[0]}: `hash-type consistent` missing: "
                                              f"a replica's loss would move every session")
        need(any(line.startswith(f"use_backend {pinned[0]} ") and f"req.hdr({SESSION_HEADER})" in line
                 for line in routing),
             f"{cfg_where}: no `use_backend {pinned[0]}` on req.hdr({SESSION_HEADER}): session calls are not pinned")
        replicas = deployment["spec"].get("replicas", 1)
        if replicas > 1:
            need(any("hash-key addr" in line for line in lines),
                 f"{where} spec.replicas: {replicas} balancers, but backend {pinned[0]} places its slots on the hash "
                 f"ring by name; each balancer fills the slots in its own DNS order, so they would disagree on "
                 f"where a session lives (needs `hash-key addr`, HAProxy >= 2.7, or one balancer)")
    need(any("balance leastconn" in lines for lines in backends.values()),
         f"{cfg_where}: no `balance leastconn` backend for the Control streams")

    # Server slots: resolved from the headless Service, on its port.
    slots = None
    headless_names = {svc["metadata"]["name"]: svc for svc in headless}
    for name, lines in backends.items():
        templates = [line.split() for line in lines if line.startswith("server-template ")]
        if not need(templates, f"{cfg_where} backend {name}: no server-template (DNS discovery of the replicas)"):
            continue
        for words in templates:
            count = int(words[2])
            slots = count if slots is None else min(slots, count)
            host, _, port = words[3].strip('"').rpartition(":")
            service = headless_names.get(host.split(".", 1)[0])
            if need(service is not None, f"{cfg_where} backend {name}: server-template resolves {host}, which is not "
                                         f"a headless Service of the server pods ({sorted(headless_names)})"):
                service_ports = {p.get("port") for p in service["spec"].get("ports", []) or []}
                need(port.isdigit() and int(port) in service_ports,
                     f"{cfg_where} backend {name}: server-template port {port} is not a port of Service "
                     f"{service['metadata']['name']} ({sorted(service_ports)})")

    # The health check, and its speed against the drain delay.
    defaults = section("defaults", "") or []
    findings += h2_health_check_findings(defaults, f"{cfg_where} defaults")
    server_defaults = next((line.split() for line in defaults if line.startswith("default-server ")), [])
    try:
        inter = haproxy_duration_s(server_defaults[server_defaults.index("inter") + 1]) \
            if "inter" in server_defaults else 2
        fall = int(server_defaults[server_defaults.index("fall") + 1]) if "fall" in server_defaults else 3
        timeout_check = next((haproxy_duration_s(line.split()[2]) for line in defaults
                              if line.startswith("timeout check ")), inter)
        noticed = inter * fall + timeout_check
        if drain is not None:
            need(noticed < drain, f"{cfg_where}: the balancer marks a NOT_SERVING replica down after up to "
                                  f"{noticed:g} s (inter x fall + timeout check), not within NUPMPC_DRAIN_DELAY_S "
                                  f"{drain:g}: new streams would reach a replica that stopped accepting")
    except (ValueError, IndexError) as error:
        findings.append(f"{cfg_where} defaults: {error}")

    # HAProxy's own verdict (Debian package haproxy, which deploy/install-deps.sh installs):
    # without it the check fails rather than passing the configuration unchecked.
    # TLS: the files it names are mounted, TLS to TLS replicas, the caller's subject header.
    findings += k8s_tls.balancer_findings(cfg_where, sections, where, deployment, container, server_config)
    haproxy = shutil.which("haproxy")
    if haproxy is None:
        findings.append(f"{cfg_where}: haproxy is not installed (deploy/install-deps.sh): `haproxy -c` not run")
    else:
        values = {name: e.get("value", "nupmpc") for name, e in env.items()}  # fieldRef: a namespace
        status, output = k8s_tls.haproxy_check(haproxy, cfg, deployment, container, dict(os.environ, **values))
        need(status == 0, f"{cfg_where}: haproxy -c failed:\n{output}")
    return slots


# ---------------------------------------------------------------------------------------------
# The self-test: each planted mistake must be caught, by a finding that names it.

# (file, text to replace (exactly once), replacement, what a finding must contain); or
# (file, a regular expression (matching once), a function of its first group, ...).
# The server's readiness probe, as deployment.yaml has it.
READINESS_HTTP = ("          readinessProbe:\n            httpGet:\n              path: /readyz\n"
                  "              port: metrics")
PLANTED = [
    ("deployment.yaml", "readinessProbe:", "readinesProbe:", "readinesProbe: unknown field of V1Container"),
    ("service.yaml", "  selector:\n    app.kubernetes.io/name: nupmpc\n    app.kubernetes.io/component: server",
     "  selector:\n    app.kubernetes.io/name: nupmpc\n    app.kubernetes.io/component: servr",
     "(Service/nupmpc-replicas) spec.selector"),
    ("deployment.yaml", "terminationGracePeriodSeconds: 30", "terminationGracePeriodSeconds: 15",
     "terminationGracePeriodSeconds: 15 s <"),
    ("configmap.yaml", 'NUPMPC_LOG_LEVEL: "info"', 'NUPMPC_LOG_LEVEL: "info"\n  NUPMPC_THREDS: "2"',
     "data.NUPMPC_THREDS: no server flag --threds"),
    ("configmap.yaml", 'NUPMPC_THREADS: "2"', "NUPMPC_THREADS: 2", "data.NUPMPC_THREADS: 2 (int) does not fit"),
    ("deployment.yaml", "              path: /healthz\n              port: metrics",
     "              path: /healthz\n              port: grpc", "livenessProbe.httpGet.port: 'grpc'"),
    ("deployment.yaml", READINESS_HTTP,
     "          readinessProbe:\n            tcpSocket:\n              port: metrics", "must be an httpGet probe"),
    ("deployment.yaml", READINESS_HTTP, "          readinessProbe:\n            grpc:\n              port: 50051",
     "the gRPC port speaks TLS"),
    ("deployment.yaml", "          readinessProbe:\n            httpGet:\n              path: /readyz",
     "          readinessProbe:\n            httpGet:\n              path: /healthz", "readinessProbe.httpGet.path"),
    # TLS wiring: Secrets, their keys, the files the flags name, the balancer's TLS and header.
    ("deployment.yaml", "secretName: nupmpc-server-tls", "secretName: nupmpc-server-tsl",
     "Secret 'nupmpc-server-tsl' is not made by"),
    ("deployment.yaml", "              - key: tokens", "              - key: token", "key 'token' is not in Secret"),
    ("deployment.yaml", "                path: server.key", "                path: server-key.pem",
     "data.NUPMPC_TLS_KEY_FILE: /etc/nupmpc/tls/server.key is not a file"),
    ("configmap.yaml", "NUPMPC_TRUSTED_BALANCER_SUBJECT:", "NUPMPC_TRUSTED_BALANCER:",
     "no server flag --trusted_balancer "),
    ("configmap.yaml", '  NUPMPC_TLS_CLIENT_CA_FILE: "/etc/nupmpc/ca/ca.pem"\n', "",
     "NUPMPC_TRUSTED_BALANCER_SUBJECT: needs NUPMPC_TLS_CLIENT_CA_FILE"),
    ("haproxy.yaml", "verify required ca-file ca.pem", "verify none ca-file ca.pem", "need `ssl verify required"),
    ("haproxy.yaml", "tcp-check connect ssl alpn h2", "tcp-check connect", "needs `tcp-check connect ssl`"),
    ("haproxy.yaml", "      http-request del-header x-nupmpc-client-subject\n", "", "without first `http-request"),
    ("haproxy.yaml", " if { ssl_c_used } { ssl_c_verify 0 }", "", "must be set only `if"),
    ("haproxy.yaml", "                path: client.pem.key", "                path: client.key",
     "crt balancer-client-tls/client.pem: its key"),
    ("haproxy.yaml", "      default-server crt balancer-client-tls/client.pem\n", "", "present none (`crt`)"),
    ("make-secrets.sh", "nupmpc-balancer-tls --cert", "nupmpc-frontend-tls --cert",
     "Secret 'nupmpc-balancer-tls' is not made by"),
    ("deployment.yaml", 'limits:\n              cpu: "2"', 'limits:\n              cpu: "4"', "limits.cpu: '4'"),
    ("deployment.yaml", "enableServiceLinks: false", "enableServiceLinks: true", "enableServiceLinks: must be false"),
    ("configmap.yaml", 'NUPMPC_MEMORY_BUDGET_MB: "3072"', 'NUPMPC_MEMORY_BUDGET_MB: "4000"',
     "NUPMPC_MEMORY_BUDGET_MB 4000 is not below"),
    ("pdb.yaml", "      app.kubernetes.io/component: server", "      app.kubernetes.io/component: balancer",
     "(PodDisruptionBudget/nupmpc-server) spec.selector.matchLabels: does not select"),
    ("hpa.yaml", "    name: nupmpc-server\n  minReplicas", "    name: nupmpc-servers\n  minReplicas",
     "spec.scaleTargetRef: apps/v1 Deployment nupmpc-servers"),
    ("hpa.yaml", "maxReplicas: 10", "maxReplicas: 12", "spec.maxReplicas: 12 exceeds"),
    ("hpa.yaml", "apiVersion: autoscaling/v2", "apiVersion: autoscaling/v3", "'autoscaling/v3' kind"),
    ("haproxy.yaml", "  replicas: 1", "  replicas: 2", "spec.replicas: 2 balancers"),
    ("haproxy.yaml", "send-binary 000047010400000001", "send-binary 000046010400000001", "health check"),
    ("haproxy.yaml", "min-recv 0 binary 00000000020801", "min-recv 0 binary 00000000020802", "tcp-check expect"),
    ("haproxy.yaml", "expect rbinary 0000000002080[12]\n", "", "tcp-check expect"),
    ("haproxy.yaml", "inter 2s fall 2", "inter 4s fall 3", "marks a NOT_SERVING replica down after up to 13"),
    ("haproxy.yaml", "            - name: CLUSTER_DOMAIN\n              value: cluster.local\n", "",
     "uses ${CLUSTER_DOMAIN}"),
    ("haproxy.yaml", "  hash-type consistent", "  hash-type map-based", "`hash-type consistent` missing"),
    ("service.yaml", "  clusterIP: None\n", "", "no headless Service"),
    ("service.yaml", "      targetPort: grpc\n      protocol: TCP\n---",
     "      targetPort: grpcs\n      protocol: TCP\n---", "spec.ports[0].targetPort: 'grpcs'"),
    ("pdb.yaml", "  maxUnavailable: 1", "  minAvailable: 3", "spec.minAvailable: 3 leaves no replica"),
    ("deployment.yaml", "  replicas: 3", "  replicas: 3   ", "trailing spaces"),
    ("deployment.yaml", "  replicas: 3", "  replicas: [3", "does not parse"),
    ("haproxy.yaml", "timeout connect 2s", "timeout connect 2x", "haproxy -c failed"),
    ("hpa.yaml", "  #         averageValue: 20m", "  #         averageValu: 20m",
     "(commented variant) spec.metrics[0].pods.target.averageValu: unknown field"),
    # The server's sources, too: log_level taken out of the flags read from the environment.
    ("../../server/server_flags.cc", ENV_LIST, lambda names: names.replace('"log_level"', '"log_level_gone"'),
     "data.NUPMPC_LOG_LEVEL: --log_level is declared"),
]


def selftest(source_dir):
    failures = 0
    with tempfile.TemporaryDirectory() as work:
        shutil.copytree(os.path.join(source_dir, "deploy", "k8s"), os.path.join(work, "deploy", "k8s"))
        os.makedirs(os.path.join(work, "server"))
        shutil.copy(os.path.join(source_dir, "server", "server_flags.cc"), os.path.join(work, "server"))
        findings, _, _ = check(work)
        if findings:
            print("FAIL: the unchanged copy already has findings:\n  " + "\n  ".join(findings))
            return 1
        for file, old, new, expected in PLANTED:
            if "haproxy -c" in expected and shutil.which("haproxy") is None:
                print(f"FAIL: haproxy is not installed (deploy/install-deps.sh): {file}: {old!r} cannot be checked")
                return 1
            path = os.path.normpath(os.path.join(work, "deploy", "k8s", file))
            with open(path, encoding="utf-8") as f:
                original = f.read()
            if isinstance(old, re.Pattern):
                matches = list(old.finditer(original))
                if len(matches) == 1:
                    group = matches[0].span(1)
                    changed = original[:group[0]] + new(original[group[0]:group[1]]) + original[group[1]:]
                old, new = old.pattern, "(its first group changed)"
            else:
                matches = [None] * original.count(old)
                changed = original.replace(old, new)
            if len(matches) != 1:
                print(f"FAIL: {file}: {old!r} occurs {len(matches)} times, not once: update PLANTED")
                failures += 1
                continue
            with open(path, "w", encoding="utf-8") as f:
                f.write(changed)
            try:
                findings, _, _ = check(work)
            finally:
                with open(path, "w", encoding="utf-8") as f:
                    f.write(original)
            caught = [x for x in findings if expected in x]
            label = f"{file}: {old.lstrip()[:40]!r} -> {new.lstrip()[:40]!r}"
            if caught:
                print(f"caught  {label}\n        {caught[0].splitlines()[0]}")
            else:
                failures += 1
                print(f"MISSED  {label}: no finding contains {expected!r}; findings:\n  " + "\n  ".join(findings))
    print(f"self-test: {len(PLANTED) - failures} passed, {failures} failed")
    return 1 if failures else 0


def main(argv):
    args = argv[1:]
    if len(args) == 2 and args[0] == "--selftest":
        return selftest(args[1])
    if len(args) != 1 or args[0].startswith("-"):
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        return 2
    findings, notes, count = check(args[0])
    for note in notes:
        print(f"note: {note}")
    for finding in findings:
        print(f"FAIL: {finding}")
    if findings:
        print(f"deploy/k8s: {len(findings)} findings in {count} documents")
        return 1
    print(f"deploy/k8s: {count} documents pass yamllint, the schema and the cross-checks")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
