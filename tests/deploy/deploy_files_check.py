#!/usr/bin/env python3
"""Checks the deploy files (deploy/) statically and by running the real server with their flags.

Each deploy file is read as a "launch": the server's command line, the files its flags name and
where those come from (a Kubernetes Secret key, a Docker secret, a systemd credential: each
ending in an operator-made file named tokens, tls.crt or tls.key, as deploy/README.md tells the
operator to create), whether its ports are exposed, and its health probes.

Static checks, per launch:
  - a non-loopback --host only with --tokens-file or --token;
  - --tls-cert and --tls-key where a port is exposed (or the host is not loopback);
  - every file flag resolves, through mounts, volumes, Secrets, secretGenerator entries, Docker
    secrets or LoadCredential=, to one operator file; every volume, Secret, PVC and named volume
    referenced exists; the default kustomization ships no Secret with data (no real secrets);
  - every health probe is `drillctl --server <loopback>:<grpc port> ... health`, over TLS with
    --tls-ca naming the same operator file as --tls-cert when the server has TLS (kubelet's
    built-in grpc probe speaks plaintext only, so it is refused then).
Run checks, per launch (with --server and --drillctl): a temp dir gets a fresh self-signed
certificate (openssl; SAN localhost and 127.0.0.1) and a tokens file; the server starts with the
file's own flags, the host rewritten to 127.0.0.1, ports to 0, the database and every operator
file mapped into the temp dir; then each of the file's probes must print SERVING, a jobs call
without the token must be refused (exit 2) and with it accepted, and the HTTP port must answer
GET /metrics over TLS verified against the certificate.

--self-test copies deploy/, breaks one thing at a time, and asserts that the check then fails
with the expected message (and that the unbroken copy passes).
"""

import argparse
import ipaddress
import json
import os
import re
import shlex
import shutil
import signal
import socket
import ssl
import subprocess
import sys
import tempfile
import time

import yaml

# The operator files (deploy/README.md): every file flag must end in one of them.
OPERATOR_FILES = ("tokens", "tls.crt", "tls.key")
# The operator file each file flag must read.
FILE_OF_FLAG = {"--tokens-file": "tokens", "--tls-cert": "tls.crt", "--tls-key": "tls.key"}
# The server's flags that name a file the deployment must provide.
FILE_FLAGS = ("--tokens-file", "--tls-cert", "--tls-key", "--config")
# The server's default --host (server/server.h, ServerOptions::host).
DEFAULT_HOST = "127.0.0.1"
# Long enough for a server start on a loaded 2-core machine (it takes well under 1 s idle).
START_TIMEOUT_S = 60


class Launch:
    """One way the deploy files start the server."""

    def __init__(self, name):
        self.name = name
        self.args = []  # the server's flags, as the file gives them
        self.files = {}  # path inside the deployment -> operator file (absolute host path)
        self.exposed = False  # ports published / exposed outside the process's own host
        self.probes = []  # drillctl argv lists (argv[0] is drillctl)
        self.errors = []


def is_loopback(host):
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def parse_flags(args):
    """{flag: value} of `--flag=value` / `--flag value` arguments (a bare flag maps to "")."""
    flags = {}
    i = 0
    while i < len(args):
        arg = args[i]
        if arg.startswith("--") and "=" in arg:
            name, value = arg.split("=", 1)
            flags[name] = value
        elif arg.startswith("--"):
            if i + 1 < len(args) and not args[i + 1].startswith("--"):
                flags[arg] = args[i + 1]
                i += 1
            else:
                flags[arg] = ""
        i += 1
    return flags


def resolve(launch, path, what):
    """The operator file of `path`, or None with an error recorded."""
    source = launch.files.get(path)
    if source is None:
        launch.errors.append(f"{what} {path}: no Secret, mount, secret or credential provides it")
        return None
    if os.path.basename(source) not in OPERATOR_FILES:
        launch.errors.append(f"{what} {path}: comes from {source}, not one of the operator files "
                             f"{', '.join(OPERATOR_FILES)} (deploy/README.md)")
        return None
    return source


def check_launch(launch):
    """The static checks; appends to launch.errors."""
    flags = parse_flags(launch.args)
    host = flags.get("--host", DEFAULT_HOST)
    has_token = bool(flags.get("--tokens-file") or flags.get("--token"))
    has_tls = bool(flags.get("--tls-cert") and flags.get("--tls-key"))
    if not is_loopback(host) and not has_token:
        launch.errors.append(f"listens on {host} without --tokens-file or --token")
    if "--allow-unauthenticated" in flags:
        launch.errors.append("--allow-unauthenticated")
    if (launch.exposed or not is_loopback(host)) and not has_tls:
        launch.errors.append("ports exposed without --tls-cert and --tls-key")
    if "--token" in flags:
        launch.errors.append("--token on the command line (ps shows it): use --tokens-file")
    for flag in FILE_FLAGS:
        if flags.get(flag):
            source = resolve(launch, flags[flag], flag)
            expected = FILE_OF_FLAG.get(flag)
            if source and expected and os.path.basename(source) != expected:
                launch.errors.append(f"{flag} {flags[flag]} comes from {source}, not from the "
                                     f"operator's {expected}")
    cert_source = launch.files.get(flags.get("--tls-cert", ""))
    if launch.exposed and not launch.probes and launch.name != "systemd":
        launch.errors.append("no health probe")
    for probe in launch.probes:
        check_probe(launch, probe, flags, has_tls, cert_source)


def check_probe(launch, probe, flags, has_tls, cert_source):
    text = " ".join(probe)
    if not probe or os.path.basename(probe[0]) != "drillctl" or probe[-1] != "health":
        launch.errors.append(f"probe is not `drillctl ... health`: {text}")
        return
    pflags = parse_flags(probe[1:-1])
    server = pflags.get("--server", "localhost:50051")
    host, _, port = server.rpartition(":")
    if not is_loopback(host):
        launch.errors.append(f"probe asks {server}, not a loopback address")
    if port != flags.get("--grpc-port", "50051"):
        launch.errors.append(f"probe asks port {port}, the server's gRPC port is "
                             f"{flags.get('--grpc-port', '50051')}")
    if has_tls:
        ca = pflags.get("--tls-ca")
        if not ca:
            launch.errors.append(f"probe without --tls-ca against a TLS server: {text}")
        elif resolve(launch, ca, "probe --tls-ca") not in (None, cert_source):
            launch.errors.append(f"probe --tls-ca {ca} is not the server's certificate "
                                 f"({cert_source})")


# ---------------------------------------------------------------------------------------------
# Kubernetes: kustomization.yaml and its resources.


def load_docs(path):
    with open(path) as f:
        return [d for d in yaml.safe_load_all(f) if d]


def kubernetes_launch(k8s_dir):
    launch = Launch("k8s")
    kustomization = load_docs(os.path.join(k8s_dir, "kustomization.yaml"))[0]
    objects = []
    for resource in kustomization.get("resources", []):
        objects += load_docs(os.path.join(k8s_dir, resource))
    by_kind = {}
    for obj in objects:
        by_kind.setdefault(obj["kind"], {})[obj["metadata"]["name"]] = obj
    # Secrets: generated from files (key -> operator file), or resources (must carry no data).
    secrets = {}
    for gen in kustomization.get("secretGenerator", []):
        keys = {}
        for entry in gen.get("files", []):
            key, _, rel = entry.partition("=") if "=" in entry else (os.path.basename(entry), "",
                                                                     entry)
            keys[key] = os.path.normpath(os.path.join(k8s_dir, rel))
        secrets[gen["name"]] = keys
    for name, secret in by_kind.get("Secret", {}).items():
        if secret.get("data") or secret.get("stringData"):
            launch.errors.append(f"Secret {name} with data in the default kustomization")
        secrets[name] = {}
    deployments = list(by_kind.get("Deployment", {}).values())
    if len(deployments) != 1:
        launch.errors.append(f"{len(deployments)} Deployments, expected 1")
        return launch
    pod = deployments[0]["spec"]["template"]["spec"]
    containers = [c for c in pod["containers"] if c["name"] == "drillbif-server"]
    if len(containers) != 1:
        launch.errors.append("no container drillbif-server")
        return launch
    container = containers[0]
    launch.args = list(container.get("command", [])[1:]) + list(container.get("args", []))
    launch.exposed = bool(container.get("ports")) or bool(by_kind.get("Service"))
    volumes = {v["name"]: v for v in pod.get("volumes", [])}
    for volume in volumes.values():
        claim = volume.get("persistentVolumeClaim", {}).get("claimName")
        if claim and claim not in by_kind.get("PersistentVolumeClaim", {}):
            launch.errors.append(f"volume {volume['name']}: no PersistentVolumeClaim {claim}")
    for mount in container.get("volumeMounts", []):
        volume = volumes.get(mount["name"])
        if volume is None:
            launch.errors.append(f"volumeMount {mount['mountPath']}: no volume {mount['name']}")
            continue
        if "secret" not in volume:
            continue
        secret_name = volume["secret"]["secretName"]
        if secret_name not in secrets:
            launch.errors.append(f"volume {mount['name']}: no Secret {secret_name}")
            continue
        if not mount.get("readOnly"):
            launch.errors.append(f"Secret volume {mount['name']} mounted writable")
        items = volume["secret"].get("items")
        pairs = ([(i["key"], i["path"]) for i in items] if items else
                 [(k, k) for k in secrets[secret_name]])
        for key, rel in pairs:
            if key in secrets[secret_name]:
                path = os.path.join(mount["mountPath"], rel)
                launch.files[path] = secrets[secret_name][key]
    flags = parse_flags(launch.args)
    db_dir = os.path.dirname(flags.get("--db", ""))
    if db_dir and db_dir not in [m["mountPath"] for m in container.get("volumeMounts", [])]:
        launch.errors.append(f"--db directory {db_dir} is not a mounted volume")
    for kind in ("readinessProbe", "livenessProbe", "startupProbe"):
        probe = container.get(kind)
        if probe is None:
            if kind != "startupProbe":
                launch.errors.append(f"no {kind}")
            continue
        if "exec" in probe:
            launch.probes.append(list(probe["exec"]["command"]))
        elif "grpc" in probe and flags.get("--tls-cert"):
            launch.errors.append(f"{kind}: kubelet's grpc probe is plaintext, the server TLS")
        else:
            launch.errors.append(f"{kind}: not an exec probe: {sorted(probe)}")
    return launch


# ---------------------------------------------------------------------------------------------
# Docker: compose.yaml and the Dockerfile (whose /run/secrets paths are compose's secrets).


def compose_secret_files(compose, compose_dir, service, launch):
    """Container path -> host file of the service's Docker secrets."""
    files = {}
    defined = compose.get("secrets", {}) or {}
    for entry in service.get("secrets", []) or []:
        source, target = ((entry, entry) if isinstance(entry, str) else
                          (entry["source"], entry.get("target", entry["source"])))
        if source not in defined or "file" not in (defined[source] or {}):
            launch.errors.append(f"secret {source}: not defined (with a file) in secrets:")
            continue
        path = target if target.startswith("/") else "/run/secrets/" + target
        files[path] = os.path.normpath(os.path.join(compose_dir, defined[source]["file"]))
    return files


def compose_launch(deploy_dir):
    launch = Launch("compose")
    compose = load_docs(os.path.join(deploy_dir, "compose.yaml"))[0]
    service = compose["services"]["drillbif"]
    command = service.get("command", [])
    launch.args = shlex.split(command) if isinstance(command, str) else list(command)
    launch.exposed = bool(service.get("ports"))
    launch.files = compose_secret_files(compose, deploy_dir, service, launch)
    for volume in service.get("volumes", []) or []:
        source = volume.split(":")[0] if isinstance(volume, str) else volume.get("source", "")
        if source and not source.startswith((".", "/")) and source not in (compose.get("volumes")
                                                                              or {}):
            launch.errors.append(f"named volume {source} not defined in volumes:")
    test = (service.get("healthcheck") or {}).get("test")
    if test:
        launch.probes.append(shlex.split(test[1]) if test[0] == "CMD-SHELL" else list(test[1:]))
    return launch


def dockerfile_launch(deploy_dir):
    launch = Launch("Dockerfile")
    with open(os.path.join(deploy_dir, "Dockerfile")) as f:
        text = f.read().replace("\\\n", " ")
    runtime = text[text.rindex("\nFROM "):]  # the last stage is the image
    for line in runtime.splitlines():
        line = line.strip()
        if line.startswith("CMD "):
            launch.args = json.loads(line[4:])
        elif line.startswith("EXPOSE "):
            launch.exposed = True
        elif line.startswith("HEALTHCHECK "):
            launch.probes.append(json.loads(line[line.index(" CMD ") + 5:]))
        elif line.startswith("ENTRYPOINT ") and "drillbif-server" not in line:
            launch.errors.append(f"ENTRYPOINT is not drillbif-server: {line}")
    compose = load_docs(os.path.join(deploy_dir, "compose.yaml"))[0]
    service = compose["services"]["drillbif"]
    launch.files = compose_secret_files(compose, deploy_dir, service, launch)
    return launch


# ---------------------------------------------------------------------------------------------
# systemd: the unit's ExecStart= and LoadCredential= lines.


def systemd_launch(deploy_dir):
    launch = Launch("systemd")
    entries = []
    with open(os.path.join(deploy_dir, "systemd", "drillbif-server.service")) as f:
        for line in f:
            line = line.strip()
            if line and not line.startswith(("#", ";", "[")) and "=" in line:
                entries.append(tuple(s.strip() for s in line.split("=", 1)))
    exec_start = [v for k, v in entries if k == "ExecStart" and v]
    if len(exec_start) != 1:
        launch.errors.append(f"{len(exec_start)} ExecStart= lines, expected 1")
        return launch
    argv = shlex.split(exec_start[0].lstrip("-@:+!"))
    if os.path.basename(argv[0]) != "drillbif-server":
        launch.errors.append(f"ExecStart runs {argv[0]}")
    credentials_dir = "/run/credentials/drillbif-server.service"
    launch.args = [re.sub(r"%d|\$\{CREDENTIALS_DIRECTORY\}|\$CREDENTIALS_DIRECTORY",
                          credentials_dir, a) for a in argv[1:]]
    for key, value in entries:
        if key == "LoadCredential":
            cred_id, _, source = value.partition(":")
            launch.files[f"{credentials_dir}/{cred_id}"] = source or cred_id
    return launch


def all_launches(deploy_dir):
    launches = [kubernetes_launch(os.path.join(deploy_dir, "k8s")), compose_launch(deploy_dir),
                dockerfile_launch(deploy_dir), systemd_launch(deploy_dir)]
    for launch in launches:
        check_launch(launch)
    return launches


# ---------------------------------------------------------------------------------------------
# Running the server with a launch's flags.


def make_operator_files(directory):
    """tokens, tls.crt and tls.key as deploy/README.md makes them; returns the token."""
    subprocess.run(["openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt",
                    "ec_paramgen_curve:P-256", "-nodes", "-days", "1", "-subj", "/CN=drillbif",
                    "-addext", "subjectAltName=DNS:localhost,IP:127.0.0.1",
                    "-keyout", os.path.join(directory, "tls.key"),
                    "-out", os.path.join(directory, "tls.crt")],
                   check=True, capture_output=True)
    token = os.urandom(32).hex()
    with open(os.path.join(directory, "tokens"), "w") as f:
        f.write(f"# test clients\ndefault {token}\n")
    return token


def run_launch(launch, server_bin, drillctl_bin, work):
    """Starts the server with the launch's flags; appends failures to launch.errors."""
    operator_dir = os.path.join(work, "operator")
    os.makedirs(operator_dir)
    token = make_operator_files(operator_dir)

    def mapped(path):
        return os.path.join(operator_dir, os.path.basename(launch.files[path]))

    args = []
    for name, value in parse_flags(launch.args).items():
        if name == "--host":
            value = "127.0.0.1"
        elif name in ("--grpc-port", "--http-port"):
            value = "0"
        elif name == "--db":
            value = os.path.join(work, "drillbif.db")
        elif name in FILE_FLAGS:
            value = mapped(value)
        args += [name, value] if value != "" else [name]
    port_file = os.path.join(work, "ports")
    args += ["--port-file", port_file]
    env = {k: v for k, v in os.environ.items() if not k.startswith("DRILLBIF_")}
    log_path = os.path.join(work, "server.log")
    with open(log_path, "w") as log:
        server = subprocess.Popen([server_bin] + args, stdout=log, stderr=subprocess.STDOUT,
                                  env=env)
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        while not os.path.exists(port_file) and server.poll() is None:
            if time.monotonic() > deadline:
                break
            time.sleep(0.05)
        if not os.path.exists(port_file):
            with open(log_path) as f:
                launch.errors.append(f"server did not start (exit {server.poll()}): "
                                     f"{' '.join(args)}\n{f.read()[-2000:]}")
            return
        with open(port_file) as f:
            grpc_port, http_port = (int(line) for line in f.read().split())
        cert = os.path.join(operator_dir, "tls.crt")

        def drillctl(argv, expect_rc, what):
            result = subprocess.run([drillctl_bin] + argv, capture_output=True, text=True,
                                    env=env, timeout=60)
            if result.returncode != expect_rc:
                launch.errors.append(f"{what}: exit {result.returncode}, expected {expect_rc}: "
                                     f"drillctl {' '.join(argv)}\n{result.stdout}{result.stderr}")
            return result.stdout

        for probe in launch.probes:
            argv = []
            for name, value in parse_flags(probe[1:-1]).items():
                if name == "--server":
                    value = f"{value.rpartition(':')[0]}:{grpc_port}"
                elif name == "--tls-ca":
                    value = mapped(value)
                argv += [name, value] if value != "" else [name]
            out = drillctl(argv + ["health"], 0, "probe")
            if out.strip() != "SERVING":
                launch.errors.append(f"probe printed {out!r}, not SERVING")
        remote = ["--server", f"localhost:{grpc_port}", "--tls-ca", cert, "--timeout", "10"]
        if launch.files.get(parse_flags(launch.args).get("--tokens-file", "")):
            drillctl(remote + ["jobs", "list"], 2, "jobs list without the token")
            drillctl(remote + ["--token", token, "jobs", "list"], 0, "jobs list with the token")
        context = ssl.create_default_context(cafile=cert)
        with socket.create_connection(("127.0.0.1", http_port), timeout=10) as raw:
            with context.wrap_socket(raw, server_hostname="localhost") as tls:
                tls.sendall(b"GET /metrics HTTP/1.1\r\nHost: localhost\r\n"
                            b"Connection: close\r\n\r\n")
                status = tls.recv(64).split(b"\r\n")[0]
        if status != b"HTTP/1.1 200 OK":
            launch.errors.append(f"HTTPS GET /metrics: {status!r}")
    except (OSError, ssl.SSLError, subprocess.TimeoutExpired) as e:
        launch.errors.append(f"run: {e!r}")
    finally:
        if server.poll() is None:
            server.send_signal(signal.SIGTERM)
            try:
                server.wait(timeout=30)
            except subprocess.TimeoutExpired:
                server.kill()
                server.wait()


def render_kustomization(launch, deploy_dir, work):
    """`kubectl kustomize` of a copy of deploy/k8s with made operator files: the Deployment's
    Secret volumes must name the generated (hash-suffixed) Secrets, holding the keys mounted."""
    k8s_copy = os.path.join(work, "k8s")
    shutil.copytree(os.path.join(deploy_dir, "k8s"), k8s_copy)
    secrets_dir = os.path.join(k8s_copy, "secrets")
    os.makedirs(secrets_dir, exist_ok=True)
    make_operator_files(secrets_dir)
    result = subprocess.run(["kubectl", "kustomize", k8s_copy], capture_output=True, text=True,
                            timeout=120)
    if result.returncode != 0:
        launch.errors.append(f"kubectl kustomize: {result.stderr.strip()}")
        return
    objects = [d for d in yaml.safe_load_all(result.stdout) if d]
    secrets = {o["metadata"]["name"]: o for o in objects if o["kind"] == "Secret"}
    for deployment in (o for o in objects if o["kind"] == "Deployment"):
        for volume in deployment["spec"]["template"]["spec"].get("volumes", []):
            name = volume.get("secret", {}).get("secretName")
            if name is not None and name not in secrets:
                launch.errors.append(f"kubectl kustomize: volume {volume['name']} names Secret "
                                     f"{name}, which the render does not hold")
    if any(s.get("type") == "kubernetes.io/tls" and sorted(s.get("data", {})) !=
           ["tls.crt", "tls.key"] for s in secrets.values()):
        launch.errors.append("kubectl kustomize: a kubernetes.io/tls Secret without exactly "
                             "tls.crt and tls.key")


def check(deploy_dir, server_bin=None, drillctl_bin=None, only=None, quiet=False):
    """All errors, as "launch: message" lines; runs the server when binaries are given."""
    errors = []
    for launch in all_launches(deploy_dir):
        if only is not None and launch.name not in only:
            continue
        if not launch.errors and server_bin:
            with tempfile.TemporaryDirectory(prefix=f"deploy-{launch.name}-") as work:
                if launch.name == "k8s" and shutil.which("kubectl"):
                    render_kustomization(launch, deploy_dir, work)
                elif launch.name == "k8s" and not quiet:
                    print("k8s: kubectl not found: the kustomization was not rendered")
                start = time.monotonic()
                run_launch(launch, server_bin, drillctl_bin, work)
                if not quiet:
                    print(f"{launch.name}: ran the server and {len(launch.probes)} probe(s) in "
                          f"{time.monotonic() - start:.1f} s")
        errors += [f"{launch.name}: {e}" for e in launch.errors]
    return errors


# ---------------------------------------------------------------------------------------------
# Self-test: deliberately broken copies must fail.

# (launch, file under deploy/, text to find (its first occurrence is replaced), replacement,
# expected error substring)
BREAKS = [
    ("k8s", "k8s/deployment.yaml", "            - --tokens-file=/etc/drillbif/auth/tokens\n", "",
     "listens on 0.0.0.0 without --tokens-file"),
    ("k8s", "k8s/deployment.yaml",
     "        - name: tls\n          secret:\n            secretName: drillbif-tls\n"
     "            defaultMode: 0440\n", "", "no volume tls"),
    ("k8s", "k8s/deployment.yaml", "secretName: drillbif-tokens", "secretName: drillbif-token",
     "no Secret drillbif-token"),
    ("k8s", "k8s/kustomization.yaml", "      - tls.key=secrets/tls.key\n", "",
     "--tls-key /etc/drillbif/tls/tls.key: no Secret"),
    ("k8s", "k8s/deployment.yaml", "            - --tls-cert=/etc/drillbif/tls/tls.crt\n", "",
     "ports exposed without --tls-cert"),
    ("k8s", "k8s/deployment.yaml", "                - --tls-ca=/etc/drillbif/tls/tls.crt\n", "",
     "probe without --tls-ca"),
    ("k8s", "k8s/deployment.yaml", "claimName: drillbif-data", "claimName: other",
     "no PersistentVolumeClaim other"),
    ("k8s", "k8s/kustomization.yaml",
     "      - tls.crt=secrets/tls.crt\n      - tls.key=secrets/tls.key\n",
     "      - tls.crt=secrets/tls.key\n      - tls.key=secrets/tls.crt\n",
     "--tls-cert /etc/drillbif/tls/tls.crt comes from"),
    ("compose", "compose.yaml", "    file: ./secrets/tokens\n", "    file: ./secrets/tls.crt\n",
     "--tokens-file /run/secrets/drillbif_tokens comes from"),
    # Only the run finds this one: every file resolves, but the server refuses a flag value.
    ("k8s", "k8s/deployment.yaml", "            - --http-port=8080\n",
     "            - --http-port=8080\n            - --log-format=yaml\n", "server did not start"),
    ("compose", "compose.yaml", "      - drillbif_tls_key\n", "",
     "--tls-key /run/secrets/drillbif_tls_key: no Secret"),
    ("compose", "compose.yaml", '"--tls-ca", "/run/secrets/drillbif_tls_cert", ', "",
     "probe without --tls-ca"),
    ("compose", "compose.yaml", "      - --tokens-file=/run/secrets/drillbif_tokens\n",
     "      - --allow-unauthenticated\n", "without --tokens-file"),
    ("Dockerfile", "Dockerfile", '"--tokens-file", "/run/secrets/drillbif_tokens", ', "",
     "without --tokens-file"),
    ("Dockerfile", "Dockerfile", '"localhost:50051"', '"localhost:8080"',
     "probe asks port 8080"),
    ("systemd", "systemd/drillbif-server.service", "LoadCredential=tokens:/etc/drillbif/tokens\n",
     "", "--tokens-file /run/credentials/drillbif-server.service/tokens: no Secret"),
    ("systemd", "systemd/drillbif-server.service", " --tls-cert %d/tls.crt --tls-key %d/tls.key",
     "", "without --tls-cert"),
]


def self_test(deploy_dir, server_bin, drillctl_bin):
    failures = []
    with tempfile.TemporaryDirectory(prefix="deploy-selftest-") as work:
        copy_dir = os.path.join(work, "deploy")
        shutil.copytree(deploy_dir, copy_dir)
        baseline = check(copy_dir, quiet=True)
        if baseline:
            failures.append(f"the unbroken copy fails: {baseline}")
        for name, rel, old, new, expected in BREAKS:
            path = os.path.join(copy_dir, rel)
            with open(path) as f:
                original = f.read()
            if old not in original:
                failures.append(f"break of {rel} is stale: {old!r} not found")
                continue
            with open(path, "w") as f:
                f.write(original.replace(old, new, 1))
            errors = check(copy_dir, server_bin, drillctl_bin, only={name}, quiet=True)
            with open(path, "w") as f:
                f.write(original)
            hit = [e for e in errors if expected in e]
            print(f"{'ok  ' if hit else 'MISS'} {rel}: -{old.strip()[:60]!r} -> "
                  f"{(hit or errors or ['no error'])[0].splitlines()[0][:110]}")
            if not hit:
                failures.append(f"{rel} broken ({old.strip()!r} -> {new.strip()!r}): expected "
                                f"{expected!r}, got {errors}")
    return failures


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--deploy-dir", required=True)
    parser.add_argument("--server", help="drillbif-server binary (else: static checks only)")
    parser.add_argument("--drillctl", help="drillctl binary")
    parser.add_argument("--self-test", action="store_true")
    args = parser.parse_args()
    if args.server and not args.drillctl:
        parser.error("--server needs --drillctl")
    if args.self_test:
        failures = self_test(args.deploy_dir, args.server, args.drillctl)
        print(f"self-test: {len(BREAKS) + 1 - len(failures)} of {len(BREAKS) + 1} copies "
              f"judged as expected")
        for failure in failures:
            print("FAIL:", failure)
        return 1 if failures else 0
    errors = check(args.deploy_dir, args.server, args.drillctl)
    failed = len({e.split(":")[0] for e in errors})
    print(f"deploy files: {failed} of 4 launches fail")
    for error in errors:
        print("FAIL:", error)
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
