#!/usr/bin/env python3
"""Side-by-side benchmark of campaign overhead: 1,000 runs of a trivial command through the iuq
local executor, the same campaign in EasyVVUQ, and the bare cost of spawning the command.

Every campaign does the same work per run: write an input file from a template (`{"f": x}`),
run `/bin/cp input.json result.json` in the run's own directory, decode `result.json`, and store
the output. Both run two commands at a time (two threads on EasyVVUQ's side).

- iuq commits every result to its SQLite store (synchronous = FULL, WAL) as it is ingested;
- EasyVVUQ, as shipped, turns SQLite's journal and syncing off and commits once at the end, so
  a crash loses every result since the start;
- the bare spawn is `cp` started 1,000 times, two at a time, exactly as the local executor
  starts it (posix_spawn from a Rust program, no directories, templates, decoding or store): the
  floor of any campaign of this command; `xargs -P 2` (fork + exec) is shown beside it.

Per-run figures are wall time / runs. Usage:
  cargo build --release -p iuq && python3 scripts/bench/campaign_local.py [--runs N] [--repeats R]
(IUQ_BIN picks another iuq binary; without a release build the debug one is used.)
"""
import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def iuq_binary():
    if "IUQ_BIN" in os.environ:
        return os.environ["IUQ_BIN"]
    for profile in ("release", "debug"):
        path = os.path.join(ROOT, "target", profile, "iuq")
        if os.path.exists(path):
            help_text = subprocess.run([path, "--help"], capture_output=True, text=True).stdout
            if " run " in help_text or "\n  run" in help_text:
                return path
    sys.exit("no iuq binary with `iuq run`: cargo build --release -p iuq")


def points(n):
    return [(i + 0.5) / n for i in range(n)]


def bench_iuq(work, n, parallel):
    iuq = iuq_binary()
    d = tempfile.mkdtemp(dir=work)
    with open(os.path.join(d, "input.json"), "w") as f:
        f.write('{"f": {{ x }}}\n')
    with open(os.path.join(d, "points.csv"), "w") as f:
        f.write("x\n" + "".join(f"{x!r}\n" for x in points(n)))
    with open(os.path.join(d, "study.toml"), "w") as f:
        f.write(f"""name = "bench"
[parameters]
x = {{ uniform = [0, 1] }}
[model]
kind = "command"
command = ["/bin/cp", "input.json", "result.json"]
templates = ["input.json"]
outputs = ["f"]
output = {{ file = "result.json", format = "json" }}
[design]
kind = "file"
file = "points.csv"
[executor]
kind = "local"
max_parallel = {parallel}
""")
    start = time.perf_counter()
    out = subprocess.run([iuq, "run", os.path.join(d, "study.toml"), "--json", "--log-interval", "1000"],
                         capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    if out.returncode != 0:
        sys.exit(f"iuq run failed: {out.stderr}")
    summary = json.loads(out.stdout)
    assert summary["counts"]["succeeded"] == n, summary
    return elapsed


def bench_easyvvuq(work, n, parallel):
    import chaospy as cp
    import easyvvuq as uq
    from concurrent.futures import ThreadPoolExecutor

    d = tempfile.mkdtemp(dir=work)
    template = os.path.join(d, "input.template")
    with open(template, "w") as f:
        f.write('{"f": $x}\n')
    params = {"x": {"type": "float", "min": 0.0, "max": 1.0, "default": 0.5}}
    encoder = uq.encoders.GenericEncoder(template_fname=template, delimiter="$", target_filename="input.json")
    decoder = uq.decoders.JSONDecoder(target_filename="result.json", output_columns=["f"])
    actions = uq.actions.Actions(
        uq.actions.CreateRunDirectory(root=d, flatten=True),
        uq.actions.Encode(encoder),
        uq.actions.ExecuteLocal("/bin/cp input.json result.json"),
        uq.actions.Decode(decoder),
    )
    start = time.perf_counter()
    campaign = uq.Campaign(name="bench", params=params, actions=actions, work_dir=d,
                           db_location=f"sqlite:///{d}/campaign.db")
    campaign.set_sampler(uq.sampling.RandomSampler(vary={"x": cp.Uniform(0.0, 1.0)}, max_num=n))
    with ThreadPoolExecutor(max_workers=parallel) as pool:
        campaign.execute(nsamples=n, pool=pool).collate()
    elapsed = time.perf_counter() - start
    results = campaign.get_collation_result()
    assert len(results) == n, len(results)
    return elapsed


def spawn_floor_binary():
    for profile in ("release", "debug"):
        path = os.path.join(ROOT, "target", profile, "examples", "spawn_floor")
        if os.path.exists(path):
            return path
    subprocess.run(["cargo", "build", "-q", "-p", "iuq-campaign", "--example", "spawn_floor"], cwd=ROOT, check=True)
    return os.path.join(ROOT, "target", "debug", "examples", "spawn_floor")


def bench_bare_spawn(work, n, parallel):
    """The command alone, started n times `parallel` at a time the way the local executor starts
    it (posix_spawn from a Rust program, crates/iuq-campaign/examples/spawn_floor.rs): no run
    directories, templates, decoding or store."""
    d = tempfile.mkdtemp(dir=work)
    with open(os.path.join(d, "input.json"), "w") as f:
        f.write('{"f": 0.5}\n')
    out = subprocess.run([spawn_floor_binary(), str(n), str(parallel), d, "/bin/cp", "input.json", "result.json"],
                         capture_output=True, text=True, check=True)
    return float(out.stdout)


def bench_xargs_spawn(work, n, parallel):
    """The command alone, started n times by `xargs -P` (fork + exec from a small C program)."""
    d = tempfile.mkdtemp(dir=work)
    with open(os.path.join(d, "input.json"), "w") as f:
        f.write('{"f": 0.5}\n')
    start = time.perf_counter()
    subprocess.run(["xargs", "-P", str(parallel), "-I{}", "/bin/cp", "input.json", "result.json"],
                   input="".join(f"{i}\n" for i in range(n)), text=True, cwd=d, check=True)
    return time.perf_counter() - start


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=1000)
    parser.add_argument("--parallel", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--skip-easyvvuq", action="store_true")
    args = parser.parse_args()
    n = args.runs
    work = tempfile.mkdtemp(prefix="iuq-bench-campaign-")
    try:
        results = {}
        benches = [("bare spawn", bench_bare_spawn), ("xargs -P spawn", bench_xargs_spawn),
                   ("iuq local executor", bench_iuq)]
        if not args.skip_easyvvuq:
            benches.append(("EasyVVUQ 1.x", bench_easyvvuq))
        # Repeats interleave the three, so that a change of machine load hits all of them.
        times = {name: [] for name, _ in benches}
        for _ in range(args.repeats):
            for name, fn in benches:
                times[name].append(fn(work, n, args.parallel))
        for name, _ in benches:
            results[name] = statistics.median(times[name])
        print(f"{n} runs of `/bin/cp input.json result.json`, {args.parallel} at a time, median of {args.repeats}")
        bare = results["bare spawn"]
        for name, t in results.items():
            per_run = t / n * 1000
            overhead = (t - bare) / n * 1000
            extra = "" if "spawn" in name else f"   overhead over bare spawn {overhead:6.3f} ms/run"
            spread = ", ".join(f"{x:.2f}" for x in sorted(times[name]))
            print(f"{name:<20} {t:7.3f} s   {per_run:6.3f} ms/run{extra}   (all: {spread} s)")
        if "EasyVVUQ 1.x" in results:
            ratio = results["EasyVVUQ 1.x"] / results["iuq local executor"]
            print(f"iuq is {ratio:.1f}× faster than EasyVVUQ, with every result committed (fsync) as it arrives;"
                  " EasyVVUQ runs with SQLite journaling and syncing off and one commit at the end")
        print(json.dumps({k: v / n * 1000 for k, v in results.items()}))
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
