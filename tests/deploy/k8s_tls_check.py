"""The TLS and caller wiring of deploy/k8s/, for k8s_manifest_check.py.

What a cluster would only show at run time, each a way the secure topology breaks:
* every Secret a Deployment mounts is made by deploy/k8s/make-secrets.sh, with the keys the
  mount's items name;
* every file the server's ConfigMap names (certificate, key, client CA, tokens) is provided by
  a Secret mount of the server container;
* with TLS on the gRPC port the probes are HTTP on the metrics port (/readyz for start-up and
  readiness, /healthz for liveness: the kubelet's gRPC probes cannot speak TLS); without TLS
  they are native gRPC probes;
* --trusted_balancer_subject only with a client CA, and then the balancer presents a client
  certificate;
* the balancer: every `crt` and `ca-file` it names is mounted (a certificate's key beside it
  as FILE.key); TLS to the replicas with `verify required` and a TLS health check when the
  replicas speak TLS; x-nupmpc-client-subject removed before the balancer sets it, set only
  for verified client certificates.
"""

import os
import re
import subprocess
import tempfile

SUBJECT_HEADER = "x-nupmpc-client-subject"
SERVER_FILES = ("NUPMPC_TLS_CERT_FILE", "NUPMPC_TLS_KEY_FILE", "NUPMPC_TLS_CLIENT_CA_FILE", "NUPMPC_AUTH_TOKENS_FILE")


def secrets_made(k8s_dir):
    """{secret name: set of keys} that make-secrets.sh creates, or None without the script."""
    path = os.path.join(k8s_dir, "make-secrets.sh")
    if not os.path.exists(path):
        return None
    with open(path, encoding="utf-8") as f:
        text = f.read().replace("\\\n", " ")
    made = {}
    for line in text.splitlines():
        m = re.search(r"create secret (tls|generic) ([\w.-]+)(.*)", line)
        if not m:
            continue
        if m.group(1) == "tls":
            made[m.group(2)] = {"tls.crt", "tls.key"}
        else:
            made[m.group(2)] = set(re.findall(r"--from-file=([\w.-]+)=", m.group(3)))
    return made


def provided_files(deployment, container):
    """{absolute path: (volume, key)} of the files the container's Secret mounts provide."""
    volumes = {v.get("name"): v for v in deployment["spec"]["template"]["spec"].get("volumes", []) or []}
    files = {}
    for mount in container.get("volumeMounts", []) or []:
        secret = volumes.get(mount.get("name"), {}).get("secret")
        if secret is None:
            continue
        for item in secret.get("items", []) or []:
            files[os.path.join(mount["mountPath"], item["path"])] = (mount["name"], item["key"])
    return files


def secret_findings(k8s_dir, deployments):
    findings = []
    made = secrets_made(k8s_dir)
    for where, deployment in deployments:
        for volume in deployment["spec"]["template"]["spec"].get("volumes", []) or []:
            secret = volume.get("secret")
            if secret is None:
                continue
            name = secret.get("secretName")
            if made is None or name not in made:
                findings.append(f"{where} volumes[{volume.get('name')}]: Secret {name!r} is not made by "
                                f"deploy/k8s/make-secrets.sh ({sorted(made or {})})")
                continue
            for item in secret.get("items", []) or []:
                if item.get("key") not in made[name]:
                    findings.append(f"{where} volumes[{volume.get('name')}].items: key {item.get('key')!r} is not "
                                    f"in Secret {name} ({sorted(made[name])})")
    return findings


def server_findings(where, deployment, container, config, cm_where):
    """The server's TLS files, flags and probes."""
    findings = []
    files = provided_files(deployment, container)
    for key in SERVER_FILES:
        if key in config and config[key] not in files:
            findings.append(f"{cm_where} data.{key}: {config[key]} is not a file any Secret mount of the server "
                            f"container provides ({sorted(files)})")
    if ("NUPMPC_TLS_CERT_FILE" in config) != ("NUPMPC_TLS_KEY_FILE" in config):
        findings.append(f"{cm_where}: NUPMPC_TLS_CERT_FILE and NUPMPC_TLS_KEY_FILE: set both or neither")
    if "NUPMPC_TRUSTED_BALANCER_SUBJECT" in config and "NUPMPC_TLS_CLIENT_CA_FILE" not in config:
        findings.append(f"{cm_where} data.NUPMPC_TRUSTED_BALANCER_SUBJECT: needs NUPMPC_TLS_CLIENT_CA_FILE (the "
                        f"server refuses to start)")
    findings += probe_findings(where, container, config)
    return findings


def probe_findings(where, container, config):
    findings = []
    cname = f"containers[{container.get('name')}]"
    ports = {p.get("name"): p.get("containerPort") for p in container.get("ports", []) or []}
    tls = "NUPMPC_TLS_CERT_FILE" in config
    metrics = re.fullmatch(r".*:(\d+)", config.get("NUPMPC_METRICS_ADDRESS", ""))
    for probe_name, path in (("readinessProbe", "/readyz"), ("livenessProbe", "/healthz"), ("startupProbe", "/readyz")):
        probe = container.get(probe_name)
        if probe is None:
            if probe_name != "startupProbe":
                findings.append(f"{where} {cname}.{probe_name}: missing")
            continue
        handlers = sorted(k for k in ("grpc", "httpGet", "tcpSocket", "exec") if k in probe)
        if not tls:
            if handlers != ["grpc"]:
                findings.append(f"{where} {cname}.{probe_name}: must be a native grpc probe (grpc.health.v1), "
                                f"has {handlers or 'no handler'}")
            elif probe["grpc"].get("port") not in ports.values():
                findings.append(f"{where} {cname}.{probe_name}.grpc.port: {probe['grpc'].get('port')} is not a "
                                f"containerPort of the container ({sorted(ports.values())})")
            continue
        if handlers != ["httpGet"]:
            findings.append(f"{where} {cname}.{probe_name}: must be an httpGet probe of the metrics port: with "
                            f"NUPMPC_TLS_CERT_FILE the gRPC port speaks TLS, which the kubelet's probes cannot "
                            f"(has {handlers or 'no handler'})")
            continue
        get = probe["httpGet"]
        port = ports.get(get.get("port"), get.get("port"))
        if metrics is None or port != int(metrics.group(1)):
            findings.append(f"{where} {cname}.{probe_name}.httpGet.port: {get.get('port')!r} is not the metrics port "
                            f"of NUPMPC_METRICS_ADDRESS ({config.get('NUPMPC_METRICS_ADDRESS', 'not set')!r})")
        if get.get("path") != path:
            findings.append(f"{where} {cname}.{probe_name}.httpGet.path: {get.get('path')!r}, expected {path}")
    return findings


def _file_words(line):
    """(keyword, path) of every certificate or CA file an HAProxy line names."""
    words = line.split()
    return [(w, words[i + 1]) for i, w in enumerate(words[:-1]) if w in ("crt", "ca-file")]


def _bases(sections):
    bases = {"crt": "", "ca-file": ""}
    for keyword, _, lines in sections:
        if keyword == "global":
            for line in lines:
                words = line.split()
                if words[0] == "crt-base":
                    bases["crt"] = words[1]
                elif words[0] == "ca-base":
                    bases["ca-file"] = words[1]
    return bases


def balancer_findings(cfg_where, sections, where, deployment, container, server_config):
    findings = []
    files = provided_files(deployment, container)
    bases = _bases(sections)
    server_side = []  # default-server, server and server-template lines
    for keyword, name, lines in sections:
        for line in lines:
            if line.split()[0] in ("default-server", "server", "server-template"):
                server_side.append(line)
            for word, path in _file_words(line):
                full = path if path.startswith("/") else os.path.join(bases[word], path)
                if full not in files:
                    findings.append(f"{cfg_where} {keyword} {name}: {word} {path} ({full}) is not a file any Secret "
                                    f"mount of the balancer provides ({sorted(files)})")
                elif word == "crt" and full + ".key" not in files:
                    findings.append(f"{cfg_where} {keyword} {name}: crt {path}: its key {full}.key is not mounted "
                                    f"(HAProxy reads a certificate's key from FILE.key)")
    defaults = [lines for keyword, _, lines in sections if keyword == "defaults"]
    if "NUPMPC_TLS_CERT_FILE" in server_config:
        joined = " ".join(server_side).split()
        if "ssl" not in joined or "verify" not in joined or joined[joined.index("verify") + 1] != "required":
            findings.append(f"{cfg_where}: the replicas speak TLS (NUPMPC_TLS_CERT_FILE): the balancer's server lines "
                            f"need `ssl verify required ca-file ...`")
        connects = [line for lines in defaults for line in lines if line.startswith("tcp-check connect")]
        if not connects or "ssl" not in connects[0].split():
            findings.append(f"{cfg_where}: the replicas speak TLS: the health check needs `tcp-check connect ssl`")
        if "NUPMPC_TRUSTED_BALANCER_SUBJECT" in server_config and "crt" not in joined:
            findings.append(f"{cfg_where}: the replicas trust a balancer's client certificate "
                            f"(NUPMPC_TRUSTED_BALANCER_SUBJECT), but its server lines present none (`crt`)")
    for keyword, name, lines in sections:
        if keyword != "frontend" or not any(line.startswith("default_backend") for line in lines):
            continue  # not a frontend of the replicas (the status page)
        removed = next((i for i, line in enumerate(lines)
                        if line.startswith("http-request del-header") and SUBJECT_HEADER in line), None)
        for i, line in enumerate(lines):
            if line.startswith("http-request set-header") and SUBJECT_HEADER in line:
                if removed is None or removed > i:
                    findings.append(f"{cfg_where} frontend {name}: sets {SUBJECT_HEADER} without first "
                                    f"`http-request del-header {SUBJECT_HEADER}`: a client could send its own")
                if "ssl_c_verify 0" not in line or "ssl_c_used" not in line:
                    findings.append(f"{cfg_where} frontend {name}: {SUBJECT_HEADER} must be set only `if "
                                    f"{{ ssl_c_used }} {{ ssl_c_verify 0 }}` (a verified client certificate)")
        if "NUPMPC_TRUSTED_BALANCER_SUBJECT" in server_config and removed is None:
            findings.append(f"{cfg_where} frontend {name}: no `http-request del-header {SUBJECT_HEADER}`: a client's "
                            f"own header would reach the replicas as the balancer's word")
    return findings


def materialize(cfg, deployment, container, work):
    """The configuration with its certificate paths moved under `work`, where a made-up
    certificate, key and CA stand in for the Secrets, so that `haproxy -c` can load them."""
    cert, key = os.path.join(work, "made.pem"), os.path.join(work, "made.key")
    subprocess.run(["openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1",
                    "-nodes", "-days", "1", "-subj", "/CN=k8s-manifest-check", "-keyout", key, "-out", cert],
                   check=True, capture_output=True)
    for path in provided_files(deployment, container):
        target = work + path
        os.makedirs(os.path.dirname(target), exist_ok=True)
        with open(key if path.endswith(".key") else cert, encoding="utf-8") as src, \
                open(target, "w", encoding="utf-8") as dst:
            dst.write(src.read())

    def moved(m):
        return f"{m.group(1)} {work}{m.group(2)}" if m.group(2).startswith("/") else m.group(0)

    return re.sub(r"\b(crt-base|ca-base|crt|ca-file) (\S+)", moved, cfg)


def haproxy_check(haproxy, cfg, deployment, container, env):
    """(exit status, output) of haproxy -c on the configuration, with stand-ins for its
    certificate files."""
    with tempfile.TemporaryDirectory() as work:
        path = os.path.join(work, "haproxy.cfg")
        with open(path, "w", encoding="utf-8") as f:
            f.write(materialize(cfg, deployment, container, work))
        run = subprocess.run([haproxy, "-c", "-f", path], env=env, capture_output=True, text=True)
    return run.returncode, run.stdout + run.stderr
