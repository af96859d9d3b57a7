#!/usr/bin/env python3
"""Checks the deploy files (deploy/) statically and by running the real server with their flags.

Each deploy file is read as one or more "launches", grouped by layout: a launch is one server
process kind (its command line, the files its flags name and where those come from: a Kubernetes
Secret key, a Docker secret, a systemd credential, each ending in an operator-made file named
tokens, tls.crt, tls.key, db_password or store_uri, as deploy/README.md tells the operator to
create), whether its ports are exposed, and its health probes. The layouts: k8s (PostgreSQL
StatefulSet, API and worker Deployments, and the keda/ and external-db/ components), k8s/single
(SQLite), compose (PostgreSQL, API and worker services), compose.single, Dockerfile, systemd.

Static checks, per launch:
  - a non-loopback --host only with --tokens-file or --token;
  - --tls-cert and --tls-key where a port is exposed (or the host is not loopback);
  - every file flag resolves, through mounts, volumes, Secrets, secretGenerator entries, Docker
    secrets or LoadCredential=, to one operator file; every volume, Secret, PVC and named volume
    referenced exists; the default kustomization ships no Secret with data (no real secrets);
  - --role api/worker only with --store; --store only with --store-password-file (the operator's
    db_password); no password in any flag or URI (password=, USER:PASSWORD@);
  - every health probe is `drillctl --server <loopback>:<grpc port> ... health`, over TLS with
    --tls-ca naming the same operator file as --tls-cert when the server has TLS (kubelet's
    built-in grpc probe speaks plaintext only, so it is refused then).
Static checks, per PostgreSQL layout: an API and a worker launch; the --store host is the
database's Service (compose service, or Kubernetes Service selecting the StatefulSet's pods); the
database's password from POSTGRES_PASSWORD_FILE naming the operator's db_password (never
POSTGRES_PASSWORD); pg_isready probes; compose services wait for the database to be healthy and
publish on 127.0.0.1 only, on distinct host ports, workers nothing; Kubernetes objects of known
apiVersion/kind, Service and PodDisruptionBudget selectors matching one workload's pods, the
ScaledObject targeting the worker Deployment and its TriggerAuthentication a generated Secret key.
With the tools installed (else skipped, saying so): `kubectl kustomize` renders the default
build, with the keda and external-db components, alone and together; `docker-compose config`
validates both compose files against Compose's schema.
Run checks (with --server and --drillctl): a temp dir gets a fresh self-signed certificate
(openssl; SAN localhost and 127.0.0.1), a tokens file and a database password; the server starts
with the launch's own flags, the host rewritten to 127.0.0.1, ports to 0, the database and every
operator file mapped into the temp dir; then each of the launch's probes must print SERVING, a
jobs call without the token must be refused (exit 2) and with it accepted (a worker's: drillctl
exits 1 saying the server does not serve the call), and the HTTP port
must answer GET /metrics over TLS verified against the certificate. A PostgreSQL layout runs one
API and one worker process on a throwaway PostgreSQL cluster (password authentication, a Unix
socket in the temp dir), the --store URI pointed at it: both as above, the worker refusing Jobs
rpcs, and a simulate job submitted through the API process must succeed, run by the worker (the
ScaledObject's query counting it while it waits, and 0 once it is done).

--self-test copies deploy/, breaks one thing at a time, and asserts that the check then fails
with the expected message (and that the unbroken copy passes).
"""

import argparse
import glob
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
import urllib.parse

import yaml

# The operator files (deploy/README.md): every file flag must end in one of them.
OPERATOR_FILES = ("tokens", "tls.crt", "tls.key", "db_password", "store_uri")
# The operator file each file flag must read.
FILE_OF_FLAG = {"--tokens-file": "tokens", "--tls-cert": "tls.crt", "--tls-key": "tls.key",
                "--store-password-file": "db_password"}
# The server's flags that name a file the deployment must provide.
FILE_FLAGS = ("--tokens-file", "--tls-cert", "--tls-key", "--config", "--store-password-file")
# The server's default --host (server/server.h, ServerOptions::host).
DEFAULT_HOST = "127.0.0.1"
# Long enough for a server start on a loaded 2-core machine (it takes well under 1 s idle).
START_TIMEOUT_S = 60
# PostgreSQL's server programs (Debian's postgresql package, scripts/setup.sh, keeps them off
# PATH); --pg-bindir overrides.
PG_BINDIR = (sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb")) or ["/initdb"])[-1][:-7]
# apiVersion/kind pairs the Kubernetes files may hold (a typo in either is caught here, not by
# the API server at apply time).
KNOWN_KINDS = {
    ("v1", "Service"), ("v1", "Secret"), ("v1", "PersistentVolumeClaim"), ("v1", "ConfigMap"),
    ("apps/v1", "Deployment"), ("apps/v1", "StatefulSet"),
    ("policy/v1", "PodDisruptionBudget"),
    ("keda.sh/v1alpha1", "ScaledObject"), ("keda.sh/v1alpha1", "TriggerAuthentication"),
}
# Where a value in a flag would be a password: libpq's password= parameter (URI or key=value).
PASSWORD_PARAM = re.compile(r"password\s*=", re.IGNORECASE)


class Launch:
    """One way the deploy files start the server."""

    def __init__(self, name):
        self.name = name
        self.args = []  # the server's flags, as the file gives them (variables expanded)
        self.files = {}  # path inside the deployment -> operator file (absolute host path)
        self.exposed = False  # ports published / exposed outside the process's own host
        self.probes = []  # drillctl argv lists (argv[0] is drillctl)
        self.store_from = None  # the operator file --store's URI comes from, if not literal
        self.errors = []


class Layout:
    """The launches of one deploy file set, checked and run together."""

    def __init__(self, name, launches=None):
        self.name = name
        self.launches = launches or []
        self.errors = []  # errors of the layout as a whole (database, selectors, renders)
        self.render = None  # callable(work) -> errors of an outside tool's checks, or None
        self.render_tool = "kubectl"  # the program render runs (skipped when not installed)
        self.queue_queries = []  # the autoscaler's SQL (jobs queued or running), run on the store

    def all_errors(self):
        errors = [f"{self.name}: {e}" for e in self.errors]
        for launch in self.launches:
            prefix = self.name if launch.name == self.name else f"{self.name}: {launch.name}"
            errors += [f"{prefix}: {e}" for e in launch.errors]
        return errors


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


def store_uri_errors(uri):
    """What is wrong with a --store URI as a deploy file gives it."""
    errors = []
    if PASSWORD_PARAM.search(uri):
        errors.append(f"a password in the --store URI {uri} (use --store-password-file)")
    parsed = urllib.parse.urlsplit(uri)
    if parsed.scheme not in ("postgresql", "postgres"):
        errors.append(f"--store {uri}: not a postgresql:// URI")
    elif parsed.password is not None:
        errors.append(f"a password in the --store URI {uri} (USER:PASSWORD@; use "
                      f"--store-password-file)")
    elif not parsed.username or not parsed.hostname or not parsed.path.strip("/"):
        errors.append(f"--store {uri}: no user, host or database (postgresql://USER@HOST:PORT/DB)")
    return errors


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
    for name, value in flags.items():
        if "password" in name and name != "--store-password-file":
            launch.errors.append(f"a password flag {name} (ps shows it): use "
                                 f"--store-password-file")
        elif PASSWORD_PARAM.search(value) and name != "--store":
            launch.errors.append(f"a password in {name} {value}")
    role = flags.get("--role", "all")
    if role in ("api", "worker") and not flags.get("--store"):
        launch.errors.append(f"--role {role} without --store (a shared PostgreSQL store)")
    if flags.get("--store"):
        if launch.store_from is None:
            launch.errors += store_uri_errors(flags["--store"])
        elif os.path.basename(launch.store_from) != "store_uri":
            launch.errors.append(f"--store comes from {launch.store_from}, not from the "
                                 f"operator's store_uri")
        if not flags.get("--store-password-file"):
            launch.errors.append("--store without --store-password-file (the password belongs "
                                 "in a mounted secret file)")
        if "--db" in flags:
            launch.errors.append("--store with --db")
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


def check_store_layout(layout, database_hosts):
    """A PostgreSQL layout: API and worker launches whose --store host is the database."""
    roles = [parse_flags(launch.args).get("--role", "all") for launch in layout.launches]
    if not any(role in ("api", "all") for role in roles):
        layout.errors.append("no API process (--role api)")
    if not any(role in ("worker", "all") for role in roles):
        layout.errors.append("no worker process (--role worker)")
    for launch in layout.launches:
        uri = parse_flags(launch.args).get("--store")
        if uri and launch.store_from is None:
            host = urllib.parse.urlsplit(uri).hostname
            if host not in database_hosts:
                launch.errors.append(f"--store host {host} is not the layout's database "
                                     f"({', '.join(sorted(database_hosts)) or 'none'})")


def check_pg_isready(what, probe, errors):
    """A database probe must be pg_isready over TCP (the image's first-start server listens on
    the socket only, so a socket probe would pass before the database is ready)."""
    if not probe or probe[0] != "pg_isready":
        errors.append(f"{what}: not pg_isready: {probe}")
    elif "-h" not in probe or not is_loopback(probe[probe.index("-h") + 1]):
        errors.append(f"{what}: pg_isready without -h 127.0.0.1 (TCP)")


# ---------------------------------------------------------------------------------------------
# Kubernetes: a kustomization and its resources.


def load_docs(path):
    with open(path) as f:
        return [d for d in yaml.safe_load_all(f) if d]


def load_kustomization(directory, errors):
    """(objects, {Secret name: {key: operator file}}) of a kustomization or component directory:
    its resource files and its secretGenerator (file paths relative to the directory)."""
    kustomization = load_docs(os.path.join(directory, "kustomization.yaml"))[0]
    objects = []
    for resource in kustomization.get("resources", []):
        objects += load_docs(os.path.join(directory, resource))
    secrets = {}
    for gen in kustomization.get("secretGenerator", []):
        keys = {}
        for entry in gen.get("files", []):
            key, _, rel = entry.partition("=") if "=" in entry else (os.path.basename(entry), "",
                                                                     entry)
            keys[key] = os.path.normpath(os.path.join(directory, rel))
        secrets[gen["name"]] = keys
    for obj in objects:
        if obj.get("kind") == "Secret":
            if obj.get("data") or obj.get("stringData"):
                errors.append(f"Secret {obj['metadata']['name']} with data in the kustomization")
            secrets[obj["metadata"]["name"]] = {}
    return objects, secrets


def selector_matches(selector, labels):
    return bool(selector) and all(labels.get(k) == v for k, v in selector.items())


def pod_files(pod, container, secrets, volumes_extra, errors):
    """Mount path -> operator file of the container's Secret volumes; records missing volumes,
    Secrets and writable Secret mounts in errors."""
    files = {}
    volumes = {v["name"]: v for v in pod.get("volumes", [])}
    for volume in volumes.values():
        claim = volume.get("persistentVolumeClaim", {}).get("claimName")
        if claim and claim not in volumes_extra.get("claims", ()):
            errors.append(f"volume {volume['name']}: no PersistentVolumeClaim {claim}")
    for mount in container.get("volumeMounts", []):
        volume = volumes.get(mount["name"])
        if volume is None:
            if mount["name"] not in volumes_extra.get("templates", ()):
                errors.append(f"volumeMount {mount['mountPath']}: no volume {mount['name']}")
            continue
        if "secret" not in volume:
            continue
        secret_name = volume["secret"]["secretName"]
        if secret_name not in secrets:
            errors.append(f"volume {mount['name']}: no Secret {secret_name}")
            continue
        if not mount.get("readOnly"):
            errors.append(f"Secret volume {mount['name']} mounted writable")
        items = volume["secret"].get("items")
        pairs = ([(i["key"], i["path"]) for i in items] if items else
                 [(k, k) for k in secrets[secret_name]])
        for key, rel in pairs:
            if key in secrets[secret_name]:
                files[os.path.join(mount["mountPath"], rel)] = secrets[secret_name][key]
    return files


def expand_env(container, secrets, launch):
    """{name: literal value} of the container's environment; a Secret-valued variable maps to
    "$(NAME)" left as is, with launch.store_from set when --store uses it."""
    values = {}
    for var in container.get("env", []) or []:
        if "value" in var:
            values[var["name"]] = str(var["value"])
        elif "secretKeyRef" in var.get("valueFrom", {}):
            ref = var["valueFrom"]["secretKeyRef"]
            source = secrets.get(ref["name"], {}).get(ref["key"])
            if source is None:
                launch.errors.append(f"env {var['name']}: no Secret {ref['name']} key {ref['key']}")
            values[var["name"]] = ("secret", source)
    return values


def kubernetes_launch(name, obj, secrets, claims):
    """The launch of a Deployment running drillbif-server, or None for other workloads."""
    pod = obj["spec"]["template"]["spec"]
    containers = [c for c in pod["containers"] if c["name"] == "drillbif-server"]
    if not containers:
        return None
    launch = Launch(name)
    container = containers[0]
    env = expand_env(container, secrets, launch)

    def expand(arg):
        # Kubernetes expands $(NAME) in args from the container's environment.
        def sub(m):
            value = env.get(m.group(1))
            if isinstance(value, tuple):
                launch.store_from = value[1] or "(missing)"
                return m.group(0)
            return value if value is not None else m.group(0)
        return re.sub(r"\$\(([A-Za-z_][A-Za-z0-9_]*)\)", sub, arg)

    launch.args = [expand(a) for a in list(container.get("command", [])[1:]) +
                   list(container.get("args", []))]
    launch.exposed = bool(container.get("ports"))
    launch.files = pod_files(pod, container, secrets, {"claims": claims}, launch.errors)
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


def check_k8s_database(layout, statefulset, secrets):
    """The PostgreSQL StatefulSet: its password from the operator's db_password as a file, its
    pg_isready probes; returns the names of the Services that reach its pods."""
    name = statefulset["metadata"]["name"]
    pod = statefulset["spec"]["template"]["spec"]
    templates = [t["metadata"]["name"] for t in statefulset["spec"].get("volumeClaimTemplates", [])]
    for container in pod["containers"]:
        env = {v["name"]: v for v in container.get("env", []) or []}
        errors = []
        files = pod_files(pod, container, secrets, {"templates": templates}, errors)
        layout.errors += [f"StatefulSet {name}: {e}" for e in errors]
        if "POSTGRES_PASSWORD" in env:
            layout.errors.append(f"StatefulSet {name}: POSTGRES_PASSWORD in the manifest (use "
                                 f"POSTGRES_PASSWORD_FILE and a Secret)")
        password_file = env.get("POSTGRES_PASSWORD_FILE", {}).get("value")
        if not password_file:
            layout.errors.append(f"StatefulSet {name}: no POSTGRES_PASSWORD_FILE")
        elif os.path.basename(files.get(password_file, "")) != "db_password":
            layout.errors.append(f"StatefulSet {name}: POSTGRES_PASSWORD_FILE {password_file} is "
                                 f"not the operator's db_password through a Secret volume")
        for kind in ("readinessProbe", "livenessProbe"):
            probe = container.get(kind)
            if probe is None or "exec" not in probe:
                layout.errors.append(f"StatefulSet {name}: no exec {kind}")
            else:
                check_pg_isready(f"StatefulSet {name} {kind}", probe["exec"]["command"],
                                 layout.errors)
    return statefulset["spec"].get("serviceName")


def check_k8s_objects(layout, objects, secrets):
    """Kinds, Services, PodDisruptionBudgets, the ScaledObject and its TriggerAuthentication."""
    by_kind = {}
    for obj in objects:
        if (obj.get("apiVersion"), obj.get("kind")) not in KNOWN_KINDS:
            layout.errors.append(f"unknown apiVersion/kind {obj.get('apiVersion')}/"
                                 f"{obj.get('kind')} ({obj.get('metadata', {}).get('name')})")
        by_kind.setdefault(obj.get("kind"), {})[obj["metadata"]["name"]] = obj
    workloads = {**by_kind.get("Deployment", {}), **by_kind.get("StatefulSet", {})}
    pod_labels = {name: w["spec"]["template"]["metadata"].get("labels", {})
                  for name, w in workloads.items()}
    for name, w in workloads.items():
        if not selector_matches(w["spec"]["selector"].get("matchLabels"), pod_labels[name]):
            layout.errors.append(f"{w['kind']} {name}: selector does not match its pods")
    for name, service in by_kind.get("Service", {}).items():
        if not any(selector_matches(service["spec"].get("selector"), labels)
                   for labels in pod_labels.values()):
            layout.errors.append(f"Service {name}: its selector matches no pods")
    for name, pdb in by_kind.get("PodDisruptionBudget", {}).items():
        selector = pdb["spec"].get("selector", {}).get("matchLabels")
        matched = [w for w, labels in pod_labels.items() if selector_matches(selector, labels)]
        if len(matched) != 1:
            layout.errors.append(f"PodDisruptionBudget {name}: selector matches "
                                 f"{len(matched)} workloads ({matched}), expected 1")
    workers = {name for name, d in by_kind.get("Deployment", {}).items()
               if any(parse_flags(c.get("args", [])).get("--role") == "worker"
                      for c in d["spec"]["template"]["spec"]["containers"])}
    if workers and not any(selector_matches(p["spec"].get("selector", {}).get("matchLabels"),
                                            pod_labels[w])
                           for p in by_kind.get("PodDisruptionBudget", {}).values()
                           for w in workers):
        layout.errors.append("no PodDisruptionBudget for the worker Deployment")
    auths = by_kind.get("TriggerAuthentication", {})
    for name, scaled in by_kind.get("ScaledObject", {}).items():
        target = scaled["spec"].get("scaleTargetRef", {})
        if target.get("kind", "Deployment") != "Deployment" or target.get("name") not in workers:
            layout.errors.append(f"ScaledObject {name}: targets {target.get('kind', 'Deployment')}"
                                 f" {target.get('name')}, not a worker Deployment "
                                 f"({', '.join(sorted(workers)) or 'none'})")
        if not (0 < scaled["spec"].get("minReplicaCount", 0) <=
                scaled["spec"].get("maxReplicaCount", 100)):
            layout.errors.append(f"ScaledObject {name}: minReplicaCount must be 1 or more (the "
                                 f"PodDisruptionBudget keeps one worker) and at most max")
        for trigger in scaled["spec"].get("triggers", []):
            ref = (trigger.get("authenticationRef") or {}).get("name")
            if ref not in auths:
                layout.errors.append(f"ScaledObject {name}: no TriggerAuthentication {ref}")
            if "password" in trigger.get("metadata", {}):
                layout.errors.append(f"ScaledObject {name}: a password in its metadata")
    for name, auth in auths.items():
        for ref in auth["spec"].get("secretTargetRef", []):
            source = secrets.get(ref["name"], {}).get(ref["key"])
            if source is None:
                layout.errors.append(f"TriggerAuthentication {name}: no Secret {ref['name']} "
                                     f"key {ref['key']}")
            elif ref["parameter"] == "password" and os.path.basename(source) != "db_password":
                layout.errors.append(f"TriggerAuthentication {name}: password from {source}")
    return by_kind


def kubernetes_layout(k8s_dir, name, components=()):
    """The layout of a kustomization directory (and the resources of its optional components,
    statically: their patches are checked on the render)."""
    layout = Layout(name)
    objects, secrets = load_kustomization(k8s_dir, layout.errors)
    for component in components:
        more_objects, more_secrets = load_kustomization(os.path.join(k8s_dir, component),
                                                        layout.errors)
        objects += more_objects
        secrets.update(more_secrets)
    by_kind = check_k8s_objects(layout, objects, secrets)
    layout.queue_queries = [t["metadata"]["query"]
                            for scaled in by_kind.get("ScaledObject", {}).values()
                            for t in scaled["spec"].get("triggers", [])
                            if t.get("type") == "postgresql"]
    claims = by_kind.get("PersistentVolumeClaim", {})
    for dep_name, deployment in by_kind.get("Deployment", {}).items():
        launch = kubernetes_launch(dep_name, deployment, secrets, claims)
        if launch is not None:
            layout.launches.append(launch)
    if not layout.launches:
        layout.errors.append("no Deployment with a container drillbif-server")
    if any(parse_flags(l.args).get("--store") for l in layout.launches):
        hosts = set()
        for statefulset in by_kind.get("StatefulSet", {}).values():
            service = check_k8s_database(layout, statefulset, secrets)
            pods = statefulset["spec"]["template"]["metadata"].get("labels", {})
            for svc_name, svc in by_kind.get("Service", {}).items():
                if svc_name == service and selector_matches(svc["spec"].get("selector"), pods):
                    hosts.add(svc_name)
        check_store_layout(layout, hosts)
    elif len(layout.launches) > 1:
        layout.errors.append(f"{len(layout.launches)} SQLite Deployments: SQLite is one process")
    return layout


def render_errors(objects, components, expect_db):
    """What must hold in a `kubectl kustomize` render with the given components."""
    errors = []
    secrets = {o["metadata"]["name"]: o for o in objects if o["kind"] == "Secret"}
    deployments = {o["metadata"]["name"]: o for o in objects if o["kind"] == "Deployment"}
    for obj in objects:
        if (obj.get("apiVersion"), obj.get("kind")) not in KNOWN_KINDS:
            errors.append(f"unknown apiVersion/kind {obj.get('apiVersion')}/{obj.get('kind')}")
    for name, deployment in deployments.items():
        pod = deployment["spec"]["template"]["spec"]
        for volume in pod.get("volumes", []):
            secret = volume.get("secret", {}).get("secretName")
            if secret is not None and secret not in secrets:
                errors.append(f"Deployment {name}: volume {volume['name']} names Secret "
                              f"{secret}, which the render does not hold")
        for container in pod["containers"]:
            for var in container.get("env", []) or []:
                ref = var.get("valueFrom", {}).get("secretKeyRef")
                if ref and ref["key"] not in secrets.get(ref["name"], {}).get("data", {}):
                    errors.append(f"Deployment {name}: env {var['name']} names Secret "
                                  f"{ref['name']} key {ref['key']}, which the render does not "
                                  f"hold")
            uri = container.get("env") and {v["name"]: v for v in container["env"]}.get(
                "DRILLBIF_STORE_URI")
            if "external-db" in components and uri and "valueFrom" not in uri:
                errors.append(f"Deployment {name}: DRILLBIF_STORE_URI not from a Secret")
    for statefulset in (o for o in objects if o["kind"] == "StatefulSet"):
        for volume in statefulset["spec"]["template"]["spec"].get("volumes", []):
            secret = volume.get("secret", {}).get("secretName")
            if secret is not None and secret not in secrets:
                errors.append(f"StatefulSet: volume {volume['name']} names missing Secret {secret}")
    has_db = any(o["kind"] == "StatefulSet" for o in objects)
    if "external-db" in components and has_db:
        errors.append("the PostgreSQL StatefulSet is still there")
    if expect_db and "external-db" not in components and not has_db:
        errors.append("no PostgreSQL StatefulSet")
    services = {o["metadata"]["name"] for o in objects if o["kind"] == "Service"}
    for scaled in (o for o in objects if o["kind"] == "ScaledObject"):
        # With the in-cluster database the scaler must name its Service (with an external one
        # the operator sets the host: deploy/README.md).
        for trigger in scaled["spec"].get("triggers", []):
            host = trigger.get("metadata", {}).get("host", "")
            if has_db and host.split(".")[0] not in services:
                errors.append(f"the ScaledObject's database host {host} is no Service of the "
                              f"render")
        target = deployments.get(scaled["spec"]["scaleTargetRef"]["name"])
        if target is None:
            errors.append("ScaledObject targets a Deployment the render does not hold")
        elif "replicas" in target["spec"]:
            errors.append("the ScaledObject's Deployment sets replicas (kubectl apply would "
                          "reset the autoscaler's count)")
    for auth in (o for o in objects if o["kind"] == "TriggerAuthentication"):
        for ref in auth["spec"].get("secretTargetRef", []):
            if ref["key"] not in secrets.get(ref["name"], {}).get("data", {}):
                errors.append(f"TriggerAuthentication names Secret {ref['name']} key "
                              f"{ref['key']}, which the render does not hold")
    if "keda" in components and not any(o["kind"] == "ScaledObject" for o in objects):
        errors.append("no ScaledObject")
    if any(s.get("type") == "kubernetes.io/tls" and sorted(s.get("data", {})) !=
           ["tls.crt", "tls.key"] for s in secrets.values()):
        errors.append("a kubernetes.io/tls Secret without exactly tls.crt and tls.key")
    return errors


def render_kustomization(k8s_dir, work, variants, expect_db):
    """`kubectl kustomize` of a copy of the directory with made operator files, once per variant
    (a tuple of components added to its kustomization.yaml; () as shipped)."""
    errors = []
    k8s_copy = os.path.join(work, "render")
    shutil.copytree(k8s_dir, k8s_copy)
    for secrets_dir in (os.path.join(k8s_copy, "secrets"),
                        os.path.join(k8s_copy, "external-db", "secrets")):
        if os.path.isdir(os.path.dirname(secrets_dir)):
            os.makedirs(secrets_dir, exist_ok=True)
            make_operator_files(secrets_dir)
    kustomization_path = os.path.join(k8s_copy, "kustomization.yaml")
    with open(kustomization_path) as f:
        shipped = f.read()
    for variant in variants:
        with open(kustomization_path, "w") as f:
            f.write(shipped + ("components:\n" + "".join(f"  - {c}\n" for c in variant)
                               if variant else ""))
        result = subprocess.run(["kubectl", "kustomize", k8s_copy], capture_output=True,
                                text=True, timeout=120)
        what = f"kubectl kustomize{' with ' + ' and '.join(variant) if variant else ''}"
        if result.returncode != 0:
            errors.append(f"{what}: {result.stderr.strip()}")
            continue
        objects = [d for d in yaml.safe_load_all(result.stdout) if d]
        errors += [f"{what}: {e}" for e in render_errors(objects, variant, expect_db)]
    return errors


# ---------------------------------------------------------------------------------------------
# Docker: compose.yaml, compose.single.yaml and the Dockerfile (whose /run/secrets paths are
# compose.single.yaml's secrets).


def compose_secret_files(compose, compose_dir, service, errors):
    """Container path -> host file of the service's Docker secrets."""
    files = {}
    defined = compose.get("secrets", {}) or {}
    for entry in service.get("secrets", []) or []:
        source, target = ((entry, entry) if isinstance(entry, str) else
                          (entry["source"], entry.get("target", entry["source"])))
        if source not in defined or "file" not in (defined[source] or {}):
            errors.append(f"secret {source}: not defined (with a file) in secrets:")
            continue
        path = target if target.startswith("/") else "/run/secrets/" + target
        files[path] = os.path.normpath(os.path.join(compose_dir, defined[source]["file"]))
    return files


def check_compose_volumes(compose, service, errors):
    for volume in service.get("volumes", []) or []:
        source = volume.split(":")[0] if isinstance(volume, str) else volume.get("source", "")
        if source and not source.startswith((".", "/")) and source not in (compose.get("volumes")
                                                                              or {}):
            errors.append(f"named volume {source} not defined in volumes:")


def is_drillbif_service(service):
    image = service.get("image", "")
    return image.startswith("drillbif") or "build" in service


def compose_service_launch(name, compose, deploy_dir, service):
    launch = Launch(name)
    command = service.get("command", [])
    launch.args = shlex.split(command) if isinstance(command, str) else list(command)
    launch.exposed = bool(service.get("ports"))
    launch.files = compose_secret_files(compose, deploy_dir, service, launch.errors)
    check_compose_volumes(compose, service, launch.errors)
    test = (service.get("healthcheck") or {}).get("test")
    if test:
        launch.probes.append(shlex.split(test[1]) if test[0] == "CMD-SHELL" else list(test[1:]))
    return launch


def compose_layout(deploy_dir, file_name, name):
    """One launch per drillbif service; the other services are the database."""
    layout = Layout(name)
    compose = load_docs(os.path.join(deploy_dir, file_name))[0]
    services = compose.get("services", {})
    drillbif = {n: s for n, s in services.items() if is_drillbif_service(s)}
    if not drillbif:
        layout.errors.append("no drillbif service")
    for service_name, service in drillbif.items():
        launch_name = name if len(drillbif) == 1 else service_name
        layout.launches.append(compose_service_launch(launch_name, compose, deploy_dir, service))
    published = {}
    for service_name, service in drillbif.items():
        role = parse_flags(compose_service_launch(service_name, compose, deploy_dir,
                                                  service).args).get("--role", "all")
        if role == "worker" and service.get("ports"):
            layout.errors.append(f"service {service_name}: a worker publishes ports (its health "
                                 f"and /metrics stay on the compose network)")
        for port in service.get("ports") or []:
            parts = str(port).split(":")
            if len(parts) != 3 or not is_loopback(parts[0]):
                layout.errors.append(f"service {service_name}: port {port} is not published on "
                                     f"127.0.0.1 only")
            elif parts[1] in published:
                layout.errors.append(f"service {service_name}: host port {parts[1]} is "
                                     f"{published[parts[1]]}'s too")
            else:
                published[parts[1]] = service_name
    stores = [parse_flags(l.args).get("--store") for l in layout.launches]
    if not any(stores):
        if len(layout.launches) > 1:
            layout.errors.append(f"{len(layout.launches)} SQLite services: SQLite is one process")
        return layout
    databases = {n for n, s in services.items() if n not in drillbif}
    for db_name in databases:
        service = services[db_name]
        env = service.get("environment") or {}
        if isinstance(env, list):
            env = dict(e.split("=", 1) for e in env)
        files = compose_secret_files(compose, deploy_dir, service, layout.errors)
        check_compose_volumes(compose, service, layout.errors)
        if "POSTGRES_PASSWORD" in env:
            layout.errors.append(f"service {db_name}: POSTGRES_PASSWORD in the file (use "
                                 f"POSTGRES_PASSWORD_FILE and a secret)")
        password_file = env.get("POSTGRES_PASSWORD_FILE")
        if os.path.basename(files.get(password_file or "", "")) != "db_password":
            layout.errors.append(f"service {db_name}: POSTGRES_PASSWORD_FILE {password_file} is "
                                 f"not the operator's db_password through a secret")
        test = (service.get("healthcheck") or {}).get("test") or ["CMD"]
        check_pg_isready(f"service {db_name} healthcheck",
                         shlex.split(test[1]) if test[0] == "CMD-SHELL" else list(test[1:]),
                         layout.errors)
        if service.get("ports"):
            layout.errors.append(f"service {db_name}: the database's port is published")
    for service_name, service in drillbif.items():
        depends = service.get("depends_on") or {}
        for db_name in databases:
            condition = (depends.get(db_name) or {}).get("condition") if isinstance(
                depends, dict) else None
            if condition != "service_healthy":
                layout.errors.append(f"service {service_name}: does not wait for {db_name} "
                                     f"(depends_on condition: service_healthy)")
    check_store_layout(layout, databases)
    return layout


def compose_config_errors(path, work):
    """`docker-compose config` (Debian's Compose v1, client side only: no daemon) validates the
    file against Compose's schema; v1 predates the top-level `name:`, so a copy without it."""
    with open(path) as f:
        text = re.sub(r"(?m)^name:.*\n", "", f.read())
    copy = os.path.join(work, "compose-config", os.path.basename(path))
    os.makedirs(os.path.dirname(copy), exist_ok=True)
    with open(copy, "w") as f:
        f.write(text)
    result = subprocess.run(["docker-compose", "-f", copy, "config", "-q"], capture_output=True,
                            text=True, timeout=120, cwd=os.path.dirname(copy))
    if result.returncode != 0:
        return [f"docker-compose config: {result.stderr.strip()}"]
    return []


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
    compose = load_docs(os.path.join(deploy_dir, "compose.single.yaml"))[0]
    service = compose["services"]["drillbif"]
    launch.files = compose_secret_files(compose, deploy_dir, service, launch.errors)
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


# ---------------------------------------------------------------------------------------------
# Running the server with a launch's flags.


def make_operator_files(directory):
    """tokens, tls.crt, tls.key, db_password and store_uri as deploy/README.md makes them;
    returns (token, database password)."""
    subprocess.run(["openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt",
                    "ec_paramgen_curve:P-256", "-nodes", "-days", "1", "-subj", "/CN=drillbif",
                    "-addext", "subjectAltName=DNS:localhost,IP:127.0.0.1",
                    "-keyout", os.path.join(directory, "tls.key"),
                    "-out", os.path.join(directory, "tls.crt")],
                   check=True, capture_output=True)
    token = os.urandom(32).hex()
    with open(os.path.join(directory, "tokens"), "w") as f:
        f.write(f"# test clients\ndefault {token}\n")
    # Without a newline, as deploy/README.md makes them: KEDA passes a Secret's bytes on as they
    # are, and Kubernetes puts store_uri's into --store.
    password = os.urandom(24).hex()
    with open(os.path.join(directory, "db_password"), "w") as f:
        f.write(password)
    with open(os.path.join(directory, "store_uri"), "w") as f:
        f.write("postgresql://drillbif@db.example:5432/drillbif?sslmode=require")
    return token, password


class PostgresCluster:
    """A throwaway PostgreSQL cluster with password (SCRAM) authentication on a Unix socket in a
    temp dir (no TCP port), as tests/support/postgres_cluster.h makes one; as root its commands
    run as the postgres user (initdb refuses root)."""

    def __init__(self, user, password):
        self.user = user
        self.dir = tempfile.mkdtemp(prefix="deploy-pg-")
        self.started = False
        self.as_postgres = ["runuser", "-u", "postgres", "--"] if os.geteuid() == 0 else []
        if os.geteuid() == 0:
            shutil.chown(self.dir, "postgres", "postgres")
        pwfile = os.path.join(self.dir, "pwfile")
        with open(pwfile, "w") as f:
            f.write(password + "\n")
        if os.geteuid() == 0:
            shutil.chown(pwfile, "postgres", "postgres")
        self.env = dict(os.environ, PGPASSWORD=password)
        self._run([f"{PG_BINDIR}/initdb", "-D", f"{self.dir}/data", "-U", user,
                   f"--pwfile={pwfile}", "-A", "scram-sha-256", "-E", "UTF8", "--no-sync"])
        self._run([f"{PG_BINDIR}/pg_ctl", "-D", f"{self.dir}/data", "-l",
                   f"{self.dir}/server.log", "-w", "-t", "60", "-o",
                   f"-c listen_addresses='' -c unix_socket_directories={self.dir} -c fsync=off",
                   "start"])
        self.started = True

    def _run(self, argv):
        result = subprocess.run(self.as_postgres + argv, capture_output=True, text=True,
                                env=self.env, timeout=120)
        if result.returncode != 0:
            raise RuntimeError(f"{' '.join(argv)}: {result.stdout}{result.stderr}")

    def create_database(self, name):
        subprocess.run([f"{PG_BINDIR}/dropdb", "--if-exists", "-h", self.dir, "-U", self.user,
                        name], check=True, capture_output=True, env=self.env)
        subprocess.run([f"{PG_BINDIR}/createdb", "-h", self.dir, "-U", self.user, name],
                       check=True, capture_output=True, env=self.env)

    def query(self, database, sql, with_password=True):
        """The first line psql prints for sql, or None when psql fails."""
        env = dict(self.env, PGPASSFILE=os.devnull)
        if not with_password:
            env.pop("PGPASSWORD")
        result = subprocess.run([f"{PG_BINDIR}/psql", "-w", "-h", self.dir, "-U", self.user,
                                 "-d", database, "-tA", "-v", "ON_ERROR_STOP=1", "-c", sql],
                                capture_output=True, text=True, env=env, timeout=60)
        return result.stdout.strip().split("\n")[0] if result.returncode == 0 else None

    def uri(self, uri):
        """A deploy file's --store URI pointed at this cluster: same user and database."""
        parsed = urllib.parse.urlsplit(uri)
        return f"postgresql://{parsed.username}@/{parsed.path.strip('/')}?host={self.dir}"

    def close(self):
        if self.started:
            subprocess.run(self.as_postgres + [f"{PG_BINDIR}/pg_ctl", "-D", f"{self.dir}/data",
                                               "-m", "fast", "-w", "stop"], capture_output=True)
        shutil.rmtree(self.dir, ignore_errors=True)


class Process:
    """A server started with a launch's flags, rewritten for this machine."""

    def __init__(self, launch, server_bin, work, operator_dir, store=None):
        self.launch = launch
        self.work = work
        os.makedirs(work, exist_ok=True)

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
            elif name == "--store":
                value = store.uri(value)
            elif name in FILE_FLAGS:
                value = mapped(value)
            args += [name, value] if value != "" else [name]
        self.port_file = os.path.join(work, "ports")
        args += ["--port-file", self.port_file]
        self.args = args
        self.env = {k: v for k, v in os.environ.items()
                    if not k.startswith(("DRILLBIF_", "PG"))}
        self.log_path = os.path.join(work, "server.log")
        with open(self.log_path, "w") as log:
            self.proc = subprocess.Popen([server_bin] + args, stdout=log,
                                         stderr=subprocess.STDOUT, env=self.env)
        self.grpc_port = self.http_port = None

    def wait_serving(self):
        """True once the port file is there; else an error on the launch."""
        deadline = time.monotonic() + START_TIMEOUT_S
        while not os.path.exists(self.port_file) and self.proc.poll() is None:
            if time.monotonic() > deadline:
                break
            time.sleep(0.05)
        if not os.path.exists(self.port_file):
            self.launch.errors.append(f"server did not start (exit {self.proc.poll()}): "
                                      f"{' '.join(self.args)}\n{self.log()[-2000:]}")
            return False
        with open(self.port_file) as f:
            self.grpc_port, self.http_port = (int(line) for line in f.read().split())
        return True

    def log(self):
        with open(self.log_path) as f:
            return f.read()

    def stop(self):
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


def drillctl(drillctl_bin, launch, argv, expect_rc, what, env=None, timeout=60):
    """Runs drillctl; records an error on the launch unless it exits expect_rc (None: any
    non-zero code)."""
    result = subprocess.run([drillctl_bin] + argv, capture_output=True, text=True,
                            env=env, timeout=timeout)
    if (result.returncode != expect_rc if expect_rc is not None else result.returncode == 0):
        launch.errors.append(f"{what}: exit {result.returncode}, expected "
                             f"{expect_rc if expect_rc is not None else 'non-zero'}: drillctl "
                             f"{' '.join(argv)}\n{result.stdout}{result.stderr}")
    return result.stdout


def https_get(port, cert, path, token=None):
    """(status line, body) of GET path over TLS, verified against cert."""
    context = ssl.create_default_context(cafile=cert)
    auth = f"Authorization: Bearer {token}\r\n" if token else ""
    with socket.create_connection(("127.0.0.1", port), timeout=10) as raw:
        with context.wrap_socket(raw, server_hostname="localhost") as tls:
            tls.sendall(f"GET {path} HTTP/1.1\r\nHost: localhost\r\n{auth}"
                        f"Connection: close\r\n\r\n".encode())
            data = b""
            while chunk := tls.recv(65536):
                data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    return head.split(b"\r\n")[0], body


def probe_process(process, drillctl_bin, operator_dir, token):
    """The launch's probes, the token check (API processes), /metrics."""
    launch = process.launch
    cert = os.path.join(operator_dir, "tls.crt")
    env = process.env
    for probe in launch.probes:
        argv = []
        for name, value in parse_flags(probe[1:-1]).items():
            if name == "--server":
                value = f"{value.rpartition(':')[0]}:{process.grpc_port}"
            elif name == "--tls-ca":
                value = os.path.join(operator_dir, os.path.basename(launch.files[value]))
            argv += [name, value] if value != "" else [name]
        out = drillctl(drillctl_bin, launch, argv + ["health"], 0, "probe", env)
        if out.strip() != "SERVING":
            launch.errors.append(f"probe printed {out!r}, not SERVING")
    remote = ["--server", f"localhost:{process.grpc_port}", "--tls-ca", cert, "--timeout", "10"]
    role = parse_flags(launch.args).get("--role", "all")
    if launch.files.get(parse_flags(launch.args).get("--tokens-file", "")):
        if role == "worker":
            # A worker serves no jobs (its gRPC Jobs rpcs are UNIMPLEMENTED): drillctl says to
            # name an API process and exits 1, token or not.
            result = subprocess.run([drillctl_bin] + remote + ["--token", token, "jobs", "list"],
                                    capture_output=True, text=True, env=env, timeout=60)
            if result.returncode != 1 or "does not serve this call" not in result.stderr:
                launch.errors.append(f"jobs list on a worker: exit {result.returncode}, expected 1 "
                                     f"saying it does not serve this call: {result.stderr}")
        else:
            drillctl(drillctl_bin, launch, remote + ["jobs", "list"], 2,
                     "jobs list without the token", env)
            drillctl(drillctl_bin, launch, remote + ["--token", token, "jobs", "list"], 0,
                     "jobs list with the token", env)
        # A worker's REST answers 501 even with the token.
        status, _ = https_get(process.http_port, cert, "/v1/operations", token)
        expected = b"HTTP/1.1 501" if role == "worker" else b"HTTP/1.1 200"
        if not status.startswith(expected):
            launch.errors.append(f"HTTPS GET /v1/operations with the token: {status!r}, "
                                 f"expected {expected.decode()}")
    status, body = https_get(process.http_port, cert, "/metrics")
    if status != b"HTTP/1.1 200 OK":
        launch.errors.append(f"HTTPS GET /metrics: {status!r}")
    elif parse_flags(launch.args).get("--store") and b"drillbif_queue_depth" not in body:
        launch.errors.append("/metrics without drillbif_queue_depth (the KEDA alternative)")
    return remote


def run_single(launch, server_bin, drillctl_bin, work):
    """One SQLite process with the launch's flags; appends failures to launch.errors."""
    operator_dir = os.path.join(work, "operator")
    os.makedirs(operator_dir)
    token, _ = make_operator_files(operator_dir)
    process = Process(launch, server_bin, os.path.join(work, "server"), operator_dir)
    try:
        if process.wait_serving():
            probe_process(process, drillctl_bin, operator_dir, token)
    except (OSError, ssl.SSLError, subprocess.TimeoutExpired) as e:
        launch.errors.append(f"run: {e!r}")
    finally:
        process.stop()
    return 1


def run_store_layout(layout, server_bin, drillctl_bin, work, quiet):
    """One API and one worker process of a PostgreSQL layout on a throwaway cluster: probes,
    tokens, /metrics, and a simulate job submitted through the API process while no worker runs
    (the layout's autoscaler queries must then count it), then run by the worker once it starts
    (the queries then count 0)."""
    by_role = {}
    for launch in layout.launches:
        by_role.setdefault(parse_flags(launch.args).get("--role", "all"), launch)
    api, worker = by_role.get("api"), by_role.get("worker")
    if api is None or worker is None:
        layout.errors.append("run: needs an API and a worker launch")
        return 0
    operator_dir = os.path.join(work, "operator")
    os.makedirs(operator_dir)
    token, password = make_operator_files(operator_dir)
    uri = parse_flags(api.args)["--store"]
    literal = api.store_from is None
    user = urllib.parse.urlsplit(uri).username if literal else "drillbif"
    database = urllib.parse.urlsplit(uri).path.strip("/") if literal else "drillbif"
    try:
        cluster = PostgresCluster(user, password)
    except (RuntimeError, OSError, subprocess.SubprocessError) as e:
        layout.errors.append(f"run: no PostgreSQL cluster: {e}")
        return 0
    processes = []

    class Store:  # --store of both launches -> the cluster (literal or from store_uri)
        @staticmethod
        def uri(value):
            return cluster.uri(f"postgresql://{user}@h/{database}" if "$(" in value else value)

    def start(launch):
        process = Process(launch, server_bin, os.path.join(work, launch.name.replace("/", "_")),
                          operator_dir, Store)
        processes.append(process)
        return process if process.wait_serving() else None

    def check_queue_depth(expected):
        for query in layout.queue_queries:
            got = cluster.query(database, query)
            if got != str(expected):
                layout.errors.append(f"the autoscaler's query {query!r} returned {got!r}, "
                                     f"expected {expected} (jobs queued or running)")

    try:
        cluster.create_database(database)
        # The cluster asks for the password: without it, no connection (so the servers below
        # connected with the password of their --store-password-file).
        if cluster.query(database, "SELECT 1", with_password=False) is not None:
            layout.errors.append("run: the cluster accepts a connection without the password")
        api_process = start(api)
        if api_process is None:
            return len(processes)
        remote = probe_process(api_process, drillctl_bin, operator_dir, token)
        env = api_process.env
        begin = time.monotonic()
        op = drillctl(drillctl_bin, api, remote + ["--token", token, "--detach", "simulate"], 0,
                      "submit through the API process", env).strip()
        if not op.startswith("operations/"):
            return len(processes)
        check_queue_depth(1)
        # Only the worker runs jobs, so the job's end proves that it claimed it from the store.
        worker_process = start(worker)
        if worker_process is None:
            return len(processes)
        probe_process(worker_process, drillctl_bin, operator_dir, token)
        drillctl(drillctl_bin, api, remote + ["--token", token, "jobs", "watch", op], 0,
                 "jobs watch", env, timeout=120)
        got = drillctl(drillctl_bin, api, remote + ["--token", token, "jobs", "get", op], 0,
                       "jobs get", env)
        if "SUCCEEDED" not in got:
            api.errors.append(f"the job submitted through the API did not succeed: {got[:500]}")
        job_id = op.split("/", 1)[1]
        if f"job {job_id} (simulate" not in worker_process.log():
            worker.errors.append(f"the worker's log does not show job {job_id}")
        check_queue_depth(0)
        if not quiet:
            print(f"{layout.name}: a simulate job through {api.name}, run by {worker.name}, in "
                  f"{time.monotonic() - begin:.1f} s; {len(layout.queue_queries)} autoscaler "
                  f"query(ies) counted it")
    except (OSError, ssl.SSLError, subprocess.SubprocessError) as e:
        layout.errors.append(f"run: {e!r}")
    finally:
        for process in processes:
            process.stop()
        cluster.close()
    return len(processes)


def all_layouts(deploy_dir):
    k8s_dir = os.path.join(deploy_dir, "k8s")
    k8s = kubernetes_layout(k8s_dir, "k8s", components=("keda",))
    k8s.render = lambda work: render_kustomization(
        k8s_dir, work, [(), ("keda",), ("external-db",), ("keda", "external-db")], expect_db=True)
    single_dir = os.path.join(k8s_dir, "single")
    k8s_single = kubernetes_layout(single_dir, "k8s/single")
    k8s_single.render = lambda work: render_kustomization(single_dir, work, [()],
                                                          expect_db=False)
    composes = [compose_layout(deploy_dir, "compose.yaml", "compose"),
                compose_layout(deploy_dir, "compose.single.yaml", "compose.single")]
    for layout, file_name in zip(composes, ("compose.yaml", "compose.single.yaml")):
        layout.render = (lambda path: lambda work: compose_config_errors(path, work))(
            os.path.join(deploy_dir, file_name))
        layout.render_tool = "docker-compose"
    layouts = [k8s, k8s_single] + composes + [Layout("Dockerfile", [dockerfile_launch(deploy_dir)]),
                                              Layout("systemd", [systemd_launch(deploy_dir)])]
    for layout in layouts:
        for launch in layout.launches:
            check_launch(launch)
    return layouts


def check(deploy_dir, server_bin=None, drillctl_bin=None, only=None, quiet=False):
    """All errors, as "layout: launch: message" lines; runs the servers when binaries are
    given."""
    errors = []
    layouts = all_layouts(deploy_dir)
    for layout in layouts:
        if only is not None and layout.name not in only:
            continue
        if not layout.all_errors() and server_bin:
            with tempfile.TemporaryDirectory(prefix="deploy-") as work:
                start = time.monotonic()
                if layout.render and shutil.which(layout.render_tool):
                    layout.errors += layout.render(work)
                elif layout.render and not quiet:
                    print(f"{layout.name}: {layout.render_tool} not found: not checked with it")
                if any(parse_flags(l.args).get("--store") for l in layout.launches):
                    ran = run_store_layout(layout, server_bin, drillctl_bin, work, quiet)
                else:
                    ran = sum(run_single(launch, server_bin, drillctl_bin,
                                         os.path.join(work, launch.name.replace("/", "_")))
                              for launch in layout.launches)
                if not quiet:
                    print(f"{layout.name}: {len(layout.launches)} launch(es) checked, {ran} "
                          f"server process(es) run, in {time.monotonic() - start:.1f} s")
        errors += layout.all_errors()
    return errors, len(layouts)


# ---------------------------------------------------------------------------------------------
# Self-test: deliberately broken copies must fail.

# (layout, file under deploy/, text to find (its first occurrence is replaced), replacement,
# expected error substring)
BREAKS = [
    ("k8s/single", "k8s/single/deployment.yaml",
     "            - --tokens-file=/etc/drillbif/auth/tokens\n", "",
     "listens on 0.0.0.0 without --tokens-file"),
    ("k8s/single", "k8s/single/deployment.yaml",
     "        - name: tls\n          secret:\n            secretName: drillbif-tls\n"
     "            defaultMode: 0440\n", "", "no volume tls"),
    ("k8s/single", "k8s/single/deployment.yaml", "secretName: drillbif-tokens",
     "secretName: drillbif-token", "no Secret drillbif-token"),
    ("k8s/single", "k8s/single/kustomization.yaml", "      - tls.key=secrets/tls.key\n", "",
     "--tls-key /etc/drillbif/tls/tls.key: no Secret"),
    ("k8s/single", "k8s/single/deployment.yaml",
     "            - --tls-cert=/etc/drillbif/tls/tls.crt\n", "",
     "ports exposed without --tls-cert"),
    ("k8s/single", "k8s/single/deployment.yaml",
     "                - --tls-ca=/etc/drillbif/tls/tls.crt\n", "", "probe without --tls-ca"),
    ("k8s/single", "k8s/single/deployment.yaml", "claimName: drillbif-data", "claimName: other",
     "no PersistentVolumeClaim other"),
    ("k8s/single", "k8s/single/kustomization.yaml",
     "      - tls.crt=secrets/tls.crt\n      - tls.key=secrets/tls.key\n",
     "      - tls.crt=secrets/tls.key\n      - tls.key=secrets/tls.crt\n",
     "--tls-cert /etc/drillbif/tls/tls.crt comes from"),
    ("compose.single", "compose.single.yaml", "    file: ./secrets/tokens\n",
     "    file: ./secrets/tls.crt\n", "--tokens-file /run/secrets/drillbif_tokens comes from"),
    # Only the run finds this one: every file resolves, but the server refuses a flag value.
    ("k8s/single", "k8s/single/deployment.yaml", "            - --http-port=8080\n",
     "            - --http-port=8080\n            - --log-format=yaml\n", "server did not start"),
    ("compose.single", "compose.single.yaml", "      - drillbif_tls_key\n", "",
     "--tls-key /run/secrets/drillbif_tls_key: no Secret"),
    ("compose.single", "compose.single.yaml", '"--tls-ca", "/run/secrets/drillbif_tls_cert", ',
     "", "probe without --tls-ca"),
    ("compose.single", "compose.single.yaml",
     "      - --tokens-file=/run/secrets/drillbif_tokens\n", "      - --allow-unauthenticated\n",
     "without --tokens-file"),
    ("Dockerfile", "Dockerfile", '"--tokens-file", "/run/secrets/drillbif_tokens", ', "",
     "without --tokens-file"),
    ("Dockerfile", "Dockerfile", '"localhost:50051"', '"localhost:8080"',
     "probe asks port 8080"),
    ("systemd", "systemd/drillbif-server.service", "LoadCredential=tokens:/etc/drillbif/tokens\n",
     "", "--tokens-file /run/credentials/drillbif-server.service/tokens: no Secret"),
    ("systemd", "systemd/drillbif-server.service", " --tls-cert %d/tls.crt --tls-key %d/tls.key",
     "", "without --tls-cert"),
    # The PostgreSQL layouts.
    ("compose", "compose.yaml", "  - --store=postgresql://drillbif@postgres:5432/drillbif\n",
     "  - --store=postgresql://drillbif@postgres:5432/drillbif?password=hunter2\n",
     "a password in the --store URI"),
    ("k8s", "k8s/api.yaml", "value: postgresql://drillbif@drillbif-postgres",
     "value: postgresql://drillbif:hunter2@drillbif-postgres", "a password in the --store URI"),
    ("compose", "compose.yaml",
     "      - --role=worker\n      - --host=0.0.0.0\n      - --grpc-port=50051\n"
     "      - --http-port=8080\n      - --store=postgresql://drillbif@postgres:5432/drillbif\n",
     "      - --role=worker\n      - --host=0.0.0.0\n      - --grpc-port=50051\n"
     "      - --http-port=8080\n", "--role worker without --store"),
    ("k8s", "k8s/worker.yaml", "            - --store=$(DRILLBIF_STORE_URI)\n", "",
     "--role worker without --store"),
    ("k8s", "k8s/keda/scaledobject.yaml", "    kind: Deployment\n    name: drillbif-worker\n",
     "    kind: Deployment\n    name: drillbif-workers\n",
     "ScaledObject drillbif-worker: targets Deployment drillbif-workers"),
    ("k8s", "k8s/keda/scaledobject.yaml", "      key: db_password\n", "      key: password\n",
     "TriggerAuthentication drillbif-postgres: no Secret drillbif-db key password"),
    ("k8s", "k8s/worker.yaml",
     "  selector:\n    matchLabels:\n      app.kubernetes.io/name: drillbif\n"
     "      app.kubernetes.io/component: worker\n---\n# Headless",
     "  selector:\n    matchLabels:\n      app.kubernetes.io/name: drillbif\n"
     "      app.kubernetes.io/component: workers\n---\n# Headless",
     "PodDisruptionBudget drillbif-worker: selector matches 0"),
    ("k8s", "k8s/worker.yaml", "            - --store-password-file=/etc/drillbif/db/db_password\n",
     "            - --store-password-file=/etc/drillbif/tls/tls.key\n",
     "--store-password-file /etc/drillbif/tls/tls.key comes from"),
    ("k8s", "k8s/postgres.yaml", "            - name: POSTGRES_PASSWORD_FILE\n"
     "              value: /etc/drillbif/db/db_password\n",
     "            - name: POSTGRES_PASSWORD\n              value: hunter2\n",
     "POSTGRES_PASSWORD in the manifest"),
    ("k8s", "k8s/api.yaml", "apiVersion: policy/v1\n", "apiVersion: policy/v1beta2\n",
     "unknown apiVersion/kind policy/v1beta2/PodDisruptionBudget"),
    ("compose", "compose.yaml", "      POSTGRES_PASSWORD_FILE: /run/secrets/db_password\n",
     "      POSTGRES_PASSWORD: hunter2\n", "POSTGRES_PASSWORD in the file"),
    ("compose", "compose.yaml", "      condition: service_healthy\n",
     "      condition: service_started\n", "does not wait for postgres"),
    ("compose", "compose.yaml", '      test: ["CMD", "pg_isready", "-h", "127.0.0.1", ',
     '      test: ["CMD", "pg_isready", ', "pg_isready without -h"),
    ("compose", "compose.yaml", '      - "127.0.0.1:50052:50051"\n',
     '      - "127.0.0.1:50051:50051"\n', "host port 50051 is api-1's too"),
    ("compose", "compose.yaml", "    deploy:\n      replicas: 2\n",
     '    ports:\n      - "127.0.0.1:9090:8080"\n', "a worker publishes ports"),
    # Only docker-compose finds this one (when installed; else the key is ignored): a misspelt
    # key.
    ("compose", "compose.yaml", "    restart: unless-stopped\n    # Over TCP",
     "    restrat: unless-stopped\n    # Over TCP", "docker-compose config"),
    # Only the render finds this one: the scaler's database host is no Service.
    ("k8s", "k8s/keda/scaledobject.yaml", "host: drillbif-postgres.default",
     "host: postgres.default",
     "kubectl kustomize with keda: the ScaledObject's database host postgres.default.svc"),
    # Only the run finds this one: the autoscaler's query no longer counts a queued job.
    ("k8s", "k8s/keda/scaledobject.yaml", "WHERE state IN (0, 1) AND", "WHERE state IN (1) AND",
     "returned '0', expected 1"),
    # Only the render finds this one: the component's patch no longer matches the Deployments.
    ("k8s", "k8s/external-db/kustomization.yaml", "                  - name: DRILLBIF_STORE_URI\n",
     "                  - name: DRILLBIF_STORE\n",
     "kubectl kustomize with external-db: Deployment drillbif-api: DRILLBIF_STORE_URI not from"),
    # Only the run finds this one: the worker's flags pass every static check, but the server
    # refuses the value (a lease under 300 ms).
    ("compose", "compose.yaml",
     "      - --store-password-file=/run/secrets/db_password\n"
     "      - --tokens-file=/run/secrets/drillbif_tokens\n"
     "      - --tls-cert=/run/secrets/drillbif_tls_cert\n"
     "      - --tls-key=/run/secrets/drillbif_tls_key\n      # One job",
     "      - --store-password-file=/run/secrets/db_password\n"
     "      - --tokens-file=/run/secrets/drillbif_tokens\n"
     "      - --tls-cert=/run/secrets/drillbif_tls_cert\n"
     "      - --tls-key=/run/secrets/drillbif_tls_key\n      - --lease-ms=0\n      # One job",
     "worker: server did not start"),
]


def self_test(deploy_dir, server_bin, drillctl_bin):
    failures = []
    with tempfile.TemporaryDirectory(prefix="deploy-selftest-") as work:
        copy_dir = os.path.join(work, "deploy")
        shutil.copytree(deploy_dir, copy_dir)
        baseline, _ = check(copy_dir, quiet=True)
        if baseline:
            failures.append(f"the unbroken copy fails: {baseline}")
        for name, rel, old, new, expected in BREAKS:
            tool = expected.split()[0]
            if tool in ("kubectl", "docker-compose") and not shutil.which(tool):
                print(f"skip {rel}: -{old.strip()[:60]!r} ({tool} not installed)")
                continue
            path = os.path.join(copy_dir, rel)
            with open(path) as f:
                original = f.read()
            if old not in original:
                failures.append(f"break of {rel} is stale: {old!r} not found")
                continue
            with open(path, "w") as f:
                f.write(original.replace(old, new, 1))
            errors, _ = check(copy_dir, server_bin, drillctl_bin, only={name}, quiet=True)
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
    parser.add_argument("--pg-bindir", help="PostgreSQL's initdb, pg_ctl, createdb, psql")
    parser.add_argument("--self-test", action="store_true")
    args = parser.parse_args()
    if args.pg_bindir:
        global PG_BINDIR
        PG_BINDIR = args.pg_bindir
    if args.server and not args.drillctl:
        parser.error("--server needs --drillctl")
    if args.self_test:
        failures = self_test(args.deploy_dir, args.server, args.drillctl)
        print(f"self-test: {len(BREAKS) + 1 - len(failures)} of {len(BREAKS) + 1} copies "
              f"judged as expected")
        for failure in failures:
            print("FAIL:", failure)
        return 1 if failures else 0
    start = time.monotonic()
    errors, count = check(args.deploy_dir, args.server, args.drillctl)
    failed = len({e.split(":")[0] for e in errors})
    print(f"deploy files: {failed} of {count} layouts fail ({time.monotonic() - start:.1f} s)")
    for error in errors:
        print("FAIL:", error)
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
