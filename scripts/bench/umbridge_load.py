#!/usr/bin/env python3
"""UM-Bridge load check: `--clients` concurrent clients send `--requests` evaluations in total to a
GP-bank model served by `iuq serve umbridge`, then the same load to the same GP bank served by the
Python package `umbridge` (scripts/bench/umbridge_gp_server.py, numpy/scipy); prints requests per
second, latencies and errors of both side by side.

The bank is the RBC surrogate of `iuq bench basis-gp-bank` (8 GPs, 3 inputs, 500 training points),
fitted once into --work. The load generator is the Rust example `umbridge_load` (one thread and one
kept-alive connection per client; every answer is checked: status 200, 8 outputs). Before the load,
both servers are asked for the same points and must agree (the models are equivalent).

Usage (Python with `umbridge`, numpy and scipy: `python3 -m pip install umbridge scipy`):
    cargo build --release -p iuq && cargo build --release -p iuq-umbridge --example umbridge_load
    python3 scripts/bench/umbridge_load.py [--requests 1000] [--clients 8] [--parallel 8]
IUQ_BIN and UMBRIDGE_LOAD_BIN override the binaries (default: target/release/...).
"""
import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
IUQ = os.environ.get("IUQ_BIN", os.path.join(ROOT, "target", "release", "iuq"))
LOAD = os.environ.get(
    "UMBRIDGE_LOAD_BIN", os.path.join(ROOT, "target", "release", "examples", "umbridge_load")
)
HERE = os.path.dirname(os.path.abspath(__file__))
BOUNDS = [("kLink", 10.0, 300.0), ("kBend", 50.0, 400.0), ("viscosityRatio", 1.0, 15.0)]
NAME = "rbc-gp"


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(url, process, seconds=120):
    import urllib.request

    deadline = time.time() + seconds
    while time.time() < deadline:
        if process.poll() is not None:
            sys.exit(f"the server at {url} exited with {process.returncode}")
        try:
            with urllib.request.urlopen(f"{url}/Info", timeout=2) as r:
                return json.load(r)
        except OSError:
            time.sleep(0.2)
    sys.exit(f"the server at {url} did not start")


def evaluate(url, points):
    import umbridge

    model = umbridge.HTTPModel(url, NAME)
    means = [v for p in points for v in model([p])[0]]
    stds = [v for p in points for v in model([p], {"computational_std": True})[1]]
    return means, stds


def run_load(url, args):
    bounds = ",".join(f"{lo}:{hi}" for _, lo, hi in BOUNDS)
    out = subprocess.run(
        [LOAD, url, NAME, "--bounds", bounds, "--requests", str(args.requests), "--clients", str(args.clients)],
        capture_output=True,
        text=True,
    )
    if not out.stdout.strip():
        sys.exit(f"the load generator failed: {out.stderr}")
    return json.loads(out.stdout)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--requests", type=int, default=1000)
    parser.add_argument("--clients", type=int, default=8)
    parser.add_argument("--parallel", type=int, default=8, help="evaluations at once (both servers)")
    parser.add_argument("--training", type=int, default=500)
    parser.add_argument("--work", default=os.path.join(tempfile.gettempdir(), "iuq-umbridge-load"))
    args = parser.parse_args()
    os.makedirs(args.work, exist_ok=True)

    bank = os.path.join(args.work, f"bank-{args.training}", "bank.json")
    if not os.path.exists(bank):
        print(f"fitting the GP bank ({args.training} training points, 8 outputs) …", file=sys.stderr)
        subprocess.run(
            [IUQ, "bench", "basis-gp-bank", "--out", os.path.dirname(bank), "--training", str(args.training),
             "--samples", "100", "--burn", "0", "--json"],
            check=True,
            capture_output=True,
        )
    study = os.path.join(args.work, "rbc-gp.toml")
    with open(study, "w") as f:
        f.write(f'name = "{NAME}"\n[parameters]\n')
        for name, lo, hi in BOUNDS:
            f.write(f"{name} = {{ uniform = [{lo}, {hi}] }}\n")

    probe = [[lo + (0.1 + 0.2 * i) * (hi - lo) for _, lo, hi in BOUNDS] for i in range(5)]
    results = {}
    servers = {
        "iuq serve umbridge (Rust)": lambda port: [
            IUQ, "serve", "umbridge", study, "--port", str(port), "--surrogate", bank,
            "--parallel", str(args.parallel), "--json",
        ],
        "umbridge.serve_models (Python)": lambda port: [
            sys.executable, os.path.join(HERE, "umbridge_gp_server.py"), bank, NAME, str(port),
            "--workers", str(args.parallel),
        ],
    }
    reference = None
    for label, command in servers.items():
        port = free_port()
        url = f"http://127.0.0.1:{port}"
        process = subprocess.Popen(command(port), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            info = wait_for(url, process)
            assert info["protocolVersion"] == 1.0 and NAME in info["models"], info
            values = evaluate(url, probe)
            if reference is None:
                reference = values
            else:
                # The means agree to round-off; the stds are differences c − ‖L⁻¹k*‖² of nearly
                # equal numbers (c ≈ 10³ in standardised units here), so they agree less closely.
                worst = [
                    max(abs(a - b) / max(1e-12, abs(b)) for a, b in zip(ours, theirs))
                    for ours, theirs in zip(values, reference)
                ]
                if worst[0] > 1e-6 or worst[1] > 1e-3:
                    sys.exit(f"the servers disagree (largest relative differences: means {worst[0]:.1e}, "
                             f"stds {worst[1]:.1e})")
                print(f"equivalence at {len(probe)} points: means agree to {worst[0]:.1e}, stds to {worst[1]:.1e} "
                      "(relative)", file=sys.stderr)
            results[label] = run_load(url, args)
        finally:
            process.terminate()
            process.wait(timeout=30)

    print(f"\n{args.clients} concurrent clients, {args.requests} evaluations of an 8-output GP bank "
          f"({args.training} training points), {args.parallel} evaluations at once per server\n")
    print(f"{'server':<32} {'req/s':>9} {'ok':>6} {'errors':>7} {'p50 ms':>8} {'p99 ms':>8} {'wall s':>7}")
    for label, r in results.items():
        errors = sum(r["errors"].values())
        print(f"{label:<32} {r['requests_per_second']:9.1f} {r['ok']:6d} {errors:7d} "
              f"{r['latency_ms']['p50']:8.2f} {r['latency_ms']['p99']:8.2f} {r['seconds']:7.2f}")
    (ours, python) = results.values()
    print(f"\nratio (Rust / Python requests per second): {ours['requests_per_second'] / python['requests_per_second']:.1f}×")
    print(json.dumps(results), file=open(os.path.join(args.work, "results.json"), "w"))
    if any(r["ok"] != args.requests for r in results.values()):
        sys.exit("some requests were not answered correctly")


if __name__ == "__main__":
    main()
