"""Static check of the compose stack's TLS wiring (deploy/compose/), without podman or images.

    compose_stack_check.py SOURCE_DIR
    compose_stack_check.py --selftest SOURCE_DIR   (plants mistakes in copies, sees each caught)

What `podman kube play` would only show at run time, each a way the secure stack breaks:
* yamllint; the YAML is one Pod; every NUPMPC_ setting of a replica is a real server flag;
* every replica has TLS (certificate, key, client CA), the tokens file and the trusted balancer
  subject, and the balancer every NUPMPC_BALANCER_* file and the replicas' name; each file on a
  read-only mount of a hostPath volume in up.sh's secrets directory, installed there for that
  container's user by stack_install_secrets (deploy/compose/stack-env.sh), a certificate's key
  beside it;
* the balancer's client certificate that stack_make_pki issues has the subject the replicas
  trust, and the replicas' certificate carries the name the balancer verifies;
* the balancer's configuration, rendered by its entry point from the YAML's environment with
  those certificates: TLS to clients (a client certificate verified when given), TLS to every
  replica with `verify required` and its client certificate, the health check over TLS, the
  subject header removed before it is set from a verified certificate; `haproxy -c` accepts it
  (when haproxy is installed);
* the --plaintext variant (plaintext-variant.py) keeps no TLS or token setting and no volume,
  and publishes on 127.0.0.1 only.
"""

import os
import re
import shutil
import stat
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from k8s_manifest_check import LINT_CONFIG, server_flags, yaml, yamllint_linter, YamlLintConfig  # noqa: E402
from k8s_tls_check import SERVER_FILES, SUBJECT_HEADER  # noqa: E402

STACK = "deploy/compose/nupmpc-stack.yaml"
STACK_ENV = "deploy/compose/stack-env.sh"
MOUNTED = "/etc/nupmpc/tls"
# The balancer's files: (variable, whether a key is read beside it as FILE.key).
BALANCER_FILES = (("NUPMPC_BALANCER_TLS_CRT", True), ("NUPMPC_BALANCER_CLIENT_CA", False),
                  ("NUPMPC_BALANCER_REPLICA_CA", False), ("NUPMPC_BALANCER_CLIENT_CRT", True))


def read(source_dir, path):
    with open(os.path.join(source_dir, path), encoding="utf-8") as f:
        return f.read()


def installed_files(env_text):
    """({role: set of files stack_install_secrets installs}, the secrets directory)."""
    block = re.search(r"local -A files=\((.*?)\)\n", env_text, re.S)
    files = {role: set(names.split()) for role, names in re.findall(r'\[(\w+)\]="([^"]*)"', block.group(1))} \
        if block else {}
    conf = re.search(r"^stack_conf_dir=(\S+)", env_text, re.M)
    secrets = re.search(r"^stack_secrets_dir=\$stack_conf_dir(\S+)", env_text, re.M)
    return files, (conf.group(1) + secrets.group(1)) if conf and secrets else None


def env_of(container):
    return {e["name"]: str(e.get("value", "")) for e in container.get("env", []) or []}


def mounted_role(pod, container, path, secrets_dir, findings, where):
    """The secrets role (hostPath directory name) whose read-only mount provides `path`."""
    volumes = {v["name"]: v for v in pod["spec"].get("volumes", []) or []}
    for mount in container.get("volumeMounts", []) or []:
        if os.path.dirname(path) != mount.get("mountPath"):
            continue
        host = (volumes.get(mount.get("name"), {}).get("hostPath") or {}).get("path", "")
        if not mount.get("readOnly"):
            findings.append(f"{where}: the mount of {mount['mountPath']} is not readOnly")
        if os.path.dirname(host) != secrets_dir:
            findings.append(f"{where}: {path} comes from {host or 'no hostPath'}, not from up.sh's {secrets_dir}/ROLE")
            return None
        return os.path.basename(host)
    findings.append(f"{where}: no volume mounted at {os.path.dirname(path)} provides {path}")
    return None


def file_findings(pod, container, variables, installed, secrets_dir, where):
    """Each (variable, key beside) names a mounted file that stack_install_secrets installs."""
    findings = []
    env = env_of(container)
    for variable, keyed in variables:
        path = env.get(variable)
        if not path:
            findings.append(f"{where}: no {variable}")
            continue
        role = mounted_role(pod, container, path, secrets_dir, findings, f"{where} {variable}")
        if role is None:
            continue
        names = [os.path.basename(path)] + ([os.path.basename(path) + ".key"] if keyed else [])
        for name in names:
            if name not in installed.get(role, set()):
                findings.append(f"{where} {variable}: {name} is not installed for role {role} by "
                                f"stack_install_secrets ({sorted(installed.get(role, set()))})")
    return findings


def make_pki(source_dir, pki):
    subprocess.run(["bash", "-c", f'. {STACK_ENV} && stack_make_pki "$1"', "bash", pki], cwd=source_dir,
                   check=True, capture_output=True)


def pki_out(source_dir, *args):
    return subprocess.run([os.path.join(source_dir, "deploy/make-pki.sh"), *args], check=True,
                          capture_output=True, text=True).stdout.strip()


def render_balancer(source_dir, balancer, pki, work):
    """(configuration, haproxy -c verdict or None) as the entry point renders it from the
    YAML's environment, the mounted files standing in from `pki`."""
    env = {k: v.replace(MOUNTED, pki) for k, v in env_of(balancer).items()}
    stub_dir = os.path.join(work, "bin")
    os.makedirs(stub_dir)
    stub = os.path.join(stub_dir, "haproxy")
    with open(stub, "w", encoding="utf-8") as f:  # the entry point execs `haproxy -W -db -f CONFIG`
        f.write('#!/bin/sh\n[ -z "$REAL_HAPROXY" ] || exec "$REAL_HAPROXY" -c -f "$4"\n')
    os.chmod(stub, stat.S_IRWXU)
    real = shutil.which("haproxy") or ""
    run = subprocess.run([os.path.join(source_dir, "deploy/haproxy/haproxy-entrypoint.sh")],
                         env={**env, "PATH": stub_dir + os.pathsep + os.environ["PATH"], "TMPDIR": work,
                              "REAL_HAPROXY": real}, capture_output=True, text=True)
    path = os.path.join(work, "haproxy.cfg")
    cfg = open(path, encoding="utf-8").read() if os.path.exists(path) else ""
    verdict = (run.returncode, run.stdout + run.stderr) if real else None
    return cfg, verdict


def balancer_config_findings(cfg, where):
    findings = []
    binds = [line for line in cfg.splitlines() if line.strip().startswith("bind ")]
    if not binds or not all(" ssl crt " in b and "verify optional ca-file" in b for b in binds):
        findings.append(f"{where}: the clients' bind is not TLS with client certificates verified: {binds}")
    servers = [line for line in cfg.splitlines() if line.strip().startswith("server ")]
    weak = [s.split()[1] for s in servers if not re.search(r"\bssl verify required ca-file \S+ verifyhost \S+", s)
            or " crt " not in s]
    if not servers or weak:
        findings.append(f"{where}: servers without TLS verified (verify required, verifyhost) and the balancer's "
                        f"client certificate: {sorted(set(weak)) or 'no servers'}")
    if "tcp-check connect ssl" not in cfg:
        findings.append(f"{where}: the health check does not connect with TLS")
    removed = cfg.find(f"http-request del-header {SUBJECT_HEADER}")
    setter = re.search(rf"http-request set-header {SUBJECT_HEADER} .*", cfg)
    if removed < 0 or not setter or setter.start() < removed:
        findings.append(f"{where}: {SUBJECT_HEADER} is not removed before the balancer sets it")
    elif "ssl_c_used" not in setter.group(0) or "ssl_c_verify 0" not in setter.group(0):
        findings.append(f"{where}: {SUBJECT_HEADER} is set without a verified client certificate")
    return findings


def plaintext_findings(source_dir, yaml_text):
    run = subprocess.run(["/usr/bin/python3", os.path.join(source_dir, "deploy/compose/plaintext-variant.py")],
                         input=yaml_text, capture_output=True, text=True)
    if run.returncode != 0:
        return [f"plaintext-variant.py failed: {run.stderr.strip()}"]
    pod = yaml.safe_load(run.stdout)
    findings = []
    for c in pod["spec"]["containers"]:
        left = [k for k in env_of(c) if re.search(r"TLS|TOKEN|TRUSTED|_CA$|_CRT$|REPLICA_NAME", k)]
        if left or c.get("volumeMounts"):
            findings.append(f"plaintext variant: {c['name']} keeps {left or c.get('volumeMounts')}")
        for p in c.get("ports", []) or []:
            if "hostPort" in p and p.get("hostIP") != "127.0.0.1":
                findings.append(f"plaintext variant: {c['name']} publishes port {p['hostPort']} beyond 127.0.0.1")
    if pod["spec"].get("volumes"):
        findings.append("plaintext variant: keeps volumes")
    return findings


def check(source_dir, yaml_text=None, env_text=None):
    """Findings (strings) about the compose stack in source_dir; the YAML's and stack-env.sh's
    text may be given instead of read (the self-test's planted copies)."""
    yaml_text = read(source_dir, STACK) if yaml_text is None else yaml_text
    env_text = read(source_dir, STACK_ENV) if env_text is None else env_text
    findings = [f"{STACK}:{p.line}: yamllint: {p.desc}"
                for p in yamllint_linter.run(yaml_text, YamlLintConfig(file=LINT_CONFIG))]
    pod = yaml.safe_load(yaml_text)
    if pod.get("kind") != "Pod":
        return findings + [f"{STACK}: not one Pod"]
    installed, secrets_dir = installed_files(env_text)
    if not installed or not secrets_dir:
        return findings + [f"{STACK_ENV}: no stack_install_secrets file lists or no stack_secrets_dir"]
    containers = pod["spec"]["containers"]
    replicas = [c for c in containers if "NUPMPC_ADDRESS" in env_of(c)]
    balancers = [c for c in containers if "NUPMPC_REPLICAS" in env_of(c)]
    if not replicas or len(balancers) != 1:
        return findings + [f"{STACK}: {len(replicas)} replicas and {len(balancers)} balancers"]
    balancer = balancers[0]
    from_env, _ = server_flags(source_dir)
    for c in replicas:
        where = f"{STACK} {c['name']}"
        env = env_of(c)
        for key in env:
            if key.startswith("NUPMPC_") and key[len("NUPMPC_"):].lower() not in from_env:
                findings.append(f"{where}: {key}: no server flag --{key[len('NUPMPC_'):].lower()} read from the "
                                f"environment (server/server_flags.cc)")
        findings += file_findings(pod, c, [(v, False) for v in SERVER_FILES], installed, secrets_dir, where)
        if not env.get("NUPMPC_TRUSTED_BALANCER_SUBJECT"):
            findings.append(f"{where}: no NUPMPC_TRUSTED_BALANCER_SUBJECT: forwarded callers are not accepted")
    findings += file_findings(pod, balancer, BALANCER_FILES, installed, secrets_dir, f"{STACK} {balancer['name']}")
    if findings:
        return list(dict.fromkeys(findings))

    with tempfile.TemporaryDirectory() as work:
        pki = os.path.join(work, "pki")
        make_pki(source_dir, pki)
        subject = pki_out(source_dir, pki, "subject", "balancer-client")
        for c in replicas:
            trusted = env_of(c)["NUPMPC_TRUSTED_BALANCER_SUBJECT"]
            if trusted != subject:
                findings.append(f"{STACK} {c['name']}: trusts {trusted!r}; stack_make_pki's balancer client "
                                f"certificate is {subject!r}")
        sans = subprocess.run(["openssl", "x509", "-noout", "-ext", "subjectAltName", "-in",
                               os.path.join(pki, os.path.basename(env_of(replicas[0])["NUPMPC_TLS_CERT_FILE"]))],
                              capture_output=True, text=True).stdout
        name = env_of(balancer).get("NUPMPC_BALANCER_REPLICA_NAME", "")
        if f"DNS:{name}" not in re.split(r"[,\s]+", sans):
            findings.append(f"{STACK} balancer: NUPMPC_BALANCER_REPLICA_NAME {name!r} is not a DNS name of the "
                            f"replicas' certificate stack_make_pki issues ({sans.strip().splitlines()[-1].strip()})")
        cfg, verdict = render_balancer(source_dir, balancer, pki, work)
        findings += balancer_config_findings(cfg, f"{STACK} balancer (rendered by haproxy-entrypoint.sh)")
        if verdict is not None and verdict[0] != 0:
            findings.append(f"{STACK} balancer: haproxy -c rejects the rendered configuration: {verdict[1].strip()}")
    return findings + plaintext_findings(source_dir, yaml_text)


def first_replaced(text, old, new):
    assert old in text, old
    return text.replace(old, new, 1)


SUBJECT_LINE = '          value: "CN=nupmpc-balancer,O=nupmpc"'
# (label, file planted in, how, a text the finding must contain)
PLANTED = [
    ("a replica without the trusted balancer subject", STACK,
     lambda t: first_replaced(t, "        - name: NUPMPC_TRUSTED_BALANCER_SUBJECT\n" + SUBJECT_LINE + "\n", ""),
     "r1: no NUPMPC_TRUSTED_BALANCER_SUBJECT"),
    ("a replica trusting another subject", STACK,
     lambda t: first_replaced(t, SUBJECT_LINE, '          value: "CN=nupmpc-balancer"'),
     "r1: trusts 'CN=nupmpc-balancer'"),
    ("a client CA file nobody installs", STACK,
     lambda t: first_replaced(t, '"/etc/nupmpc/tls/ca.pem"', '"/etc/nupmpc/tls/client-ca.pem"'),
     "client-ca.pem is not installed"),
    ("a writable secrets mount", STACK, lambda t: first_replaced(t, "readOnly: true", "readOnly: false"),
     "is not readOnly"),
    ("a misspelt server flag", STACK, lambda t: first_replaced(t, "NUPMPC_TLS_RELOAD_INTERVAL_S",
                                                               "NUPMPC_TLS_RELOAD_INTERVAL"),
     "no server flag --tls_reload_interval"),
    ("the balancer verifying another replica name", STACK,
     lambda t: first_replaced(t, 'value: "localhost"', 'value: "nupmpc-replicas"'),
     "'nupmpc-replicas' is not a DNS name"),
    ("the balancer without the replicas' CA", STACK,
     lambda t: first_replaced(t, "        - name: NUPMPC_BALANCER_REPLICA_CA\n          value: \"/etc/nupmpc/tls/ca.pem\"\n",
                              ""),
     "no NUPMPC_BALANCER_REPLICA_CA"),
    ("the tokens file not installed", STACK_ENV,
     lambda t: first_replaced(t, '[replica]="ca.pem tokens ', '[replica]="ca.pem '),
     "tokens is not installed for role replica"),
]


def selftest(source_dir):
    failures = 0
    clean = check(source_dir)
    if clean:
        print("self-test: the unchanged stack has findings:\n  " + "\n  ".join(clean))
        return 1
    for label, path, plant, expected in PLANTED:
        text = plant(read(source_dir, path))
        findings = check(source_dir, yaml_text=text if path == STACK else None,
                         env_text=text if path == STACK_ENV else None)
        caught = [f for f in findings if expected in f]
        if caught:
            print(f"caught  {label}\n        {caught[0]}")
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
    findings = check(args[0])
    for finding in findings:
        print(f"FAIL: {finding}")
    if findings:
        print(f"deploy/compose: {len(findings)} findings")
        return 1
    print("deploy/compose: the secure stack's TLS wiring and the plaintext variant pass"
          + ("" if shutil.which("haproxy") else " (haproxy -c not run: no haproxy)"))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
