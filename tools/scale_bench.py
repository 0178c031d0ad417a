#!/usr/bin/env python3
"""Scale-out bench: generate jobs per minute with 1, 2 and 4 worker processes.

One API process (`choreo serve --no-workers`) and N worker processes (`choreo worker --workers 1`)
share a throwaway PostgreSQL 15 (Debian's package; initdb in a temp dir, run as the `postgres`
user when we are root) and one data dir, as on one host of a scaled-out deployment. For each N the
same batch of dance-revolution jobs on a real song is submitted at once and timed from the first
POST to the last success; the machine's CPU busy share over that span says what limits it.

Not a test: it prints figures and ratios against the 1-worker run of the same invocation.

    python3 tools/scale_bench.py [--jobs 16] [--workers 1,2,4] [--song ../shared/audio/hungarian_dance_5.ogg]

Standard library only. Needs a release build (target/release/choreo) and the committed models.
"""
import argparse
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
import uuid

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def pg_bin():
    base = "/usr/lib/postgresql"
    versions = sorted((int(v), v) for v in os.listdir(base) if v.isdigit() and os.path.isfile(f"{base}/{v}/bin/initdb"))
    if not versions:
        sys.exit("PostgreSQL is not installed (bash scripts/setup.sh --test installs it)")
    return f"{base}/{versions[-1][1]}/bin"


def as_postgres(cmd):
    # PostgreSQL refuses to run as root.
    return ["setpriv", "--reuid=postgres", "--regid=postgres", "--init-groups", "--"] + cmd if os.geteuid() == 0 else cmd


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_postgres(tmp):
    pg = os.path.join(tmp, "pg")
    os.makedirs(pg)
    if os.geteuid() == 0:
        shutil.chown(pg, "postgres", "postgres")
    data = os.path.join(pg, "data")
    subprocess.run(as_postgres([f"{pg_bin()}/initdb", "-D", data, "-U", "choreo", "--auth=trust", "--no-sync", "--no-instructions"]),
                   check=True, stdout=subprocess.DEVNULL)
    port = free_port()
    log = open(os.path.join(tmp, "postgres.log"), "w")
    proc = subprocess.Popen(as_postgres([f"{pg_bin()}/postgres", "-D", data, "-p", str(port), "-c", "listen_addresses=127.0.0.1",
                                         "-k", pg, "-c", "max_connections=200"]), stdout=subprocess.DEVNULL, stderr=log)
    deadline = time.time() + 30
    while time.time() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            if "ready to accept connections" in open(os.path.join(tmp, "postgres.log")).read():
                return proc, f"postgres://choreo@127.0.0.1:{port}/postgres"
        except OSError:
            pass
        time.sleep(0.1)
    sys.exit("postgres did not start: " + open(os.path.join(tmp, "postgres.log")).read())


def choreo(args, data_dir, db_url):
    env = dict(os.environ, CHOREO_DATABASE_URL=db_url, RUST_LOG="warn", OMP_WAIT_POLICY="PASSIVE")
    cmd = [os.path.join(ROOT, "target/release/choreo")] + args + ["--data-dir", data_dir, "--models-dir", os.path.join(ROOT, "models")]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, text=True)
    return proc, proc.stdout.readline().strip()


def request(method, url, body=None, headers=None):
    req = urllib.request.Request(url, data=body, method=method, headers=headers or {})
    with urllib.request.urlopen(req, timeout=60) as r:
        return json.loads(r.read())


def upload(base, path):
    boundary = uuid.uuid4().hex
    data = open(path, "rb").read()
    body = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"{os.path.basename(path)}\"\r\n"
            f"Content-Type: application/octet-stream\r\n\r\n").encode() + data + f"\r\n--{boundary}--\r\n".encode()
    return request("POST", f"{base}/v1/songs", body, {"Content-Type": f"multipart/form-data; boundary={boundary}"})


def cpu_times():
    fields = [int(x) for x in open("/proc/stat").readline().split()[1:]]
    idle = fields[3] + fields[4]
    return sum(fields), idle


def wait(base, ids, deadline_s):
    deadline = time.time() + deadline_s
    pending = set(ids)
    while pending:
        for i in list(pending):
            job = request("GET", f"{base}/v1/jobs/{i}")
            if job["status"] == "succeeded":
                pending.discard(i)
            elif job["status"] in ("failed", "cancelled"):
                sys.exit(f"job {i} {job['status']}: {job.get('error')}")
        if time.time() > deadline:
            sys.exit(f"{len(pending)} jobs not done after {deadline_s} s")
        time.sleep(0.2)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=16)
    ap.add_argument("--workers", default="1,2,4")
    ap.add_argument("--song", default=os.path.join(ROOT, "..", "shared", "audio", "hungarian_dance_5.ogg"))
    ap.add_argument("--model", default="dance-revolution")
    args = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="choreo-scale-bench-")
    os.chmod(tmp, 0o755)  # the postgres user must reach its folder inside
    procs = []
    try:
        pg, db_url = start_postgres(tmp)
        procs.append(pg)
        data = os.path.join(tmp, "data")
        api, line = choreo(["serve", "--no-workers", "--bind", "127.0.0.1:0"], data, db_url)
        procs.append(api)
        base = line.removeprefix("choreo listening on ")
        song = upload(base, args.song)
        # The upload's analyze job needs a worker; one runs until the song is ready.
        w, _ = choreo(["worker", "--workers", "1"], data, db_url)
        while request("GET", f"{base}/v1/songs/{song['id']}").get("analysis_status") != "succeeded":
            time.sleep(0.2)
        w.terminate(); w.wait()
        rows = []
        for n in [int(x) for x in args.workers.split(",")]:
            workers = [choreo(["worker", "--workers", "1"], data, db_url)[0] for _ in range(n)]
            total0, idle0 = cpu_times()
            t0 = time.time()
            ids = [request("POST", f"{base}/v1/jobs", json.dumps({"song_id": song["id"], "model": args.model, "seed": n * 1000 + k}).encode(),
                           {"Content-Type": "application/json"})["id"] for k in range(args.jobs)]
            wait(base, ids, 1800)
            wall = time.time() - t0
            total1, idle1 = cpu_times()
            busy = 1 - (idle1 - idle0) / max(1, total1 - total0)
            for w in workers:
                w.terminate()
            for w in workers:
                w.wait()
            rows.append((n, wall, args.jobs / wall * 60, busy))
            print(f"{n} worker process(es): {args.jobs} jobs in {wall:.1f} s, {args.jobs / wall * 60:.1f} jobs/min, CPU busy {busy:.0%}", flush=True)
        one = rows[0][2]
        print(f"\nmodel {args.model}, song {os.path.basename(args.song)} ({song.get('duration_s', 0):.0f} s), {os.cpu_count()} CPU cores")
        print("| worker processes | jobs/min | vs 1 worker | CPU busy |\n|---|---|---|---|")
        for n, wall, rate, busy in rows:
            print(f"| {n} | {rate:.1f} | {rate / one:.2f}x | {busy:.0%} |")
    finally:
        for p in reversed(procs):
            p.terminate()
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
