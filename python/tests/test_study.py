"""iuq.Study: the pipeline (adaptive engine included) against `iuq pipeline`, status, export."""

import shutil

import numpy as np
import pytest

import iuq
from conftest import REPO


def copy_cooling(tmp_path, name):
    target = tmp_path / name
    shutil.copytree(REPO / "examples" / "cooling", target,
                    ignore=shutil.ignore_patterns("*.campaign", "*.campaign.previous-*"))
    return target


def without_timings(value):
    """The value with every wall-clock `seconds` left out (they differ from run to run)."""
    if isinstance(value, dict):
        return {k: without_timings(v) for k, v in value.items() if k != "seconds"}
    if isinstance(value, list):
        return [without_timings(v) for v in value]
    return value


@pytest.fixture(scope="module")
def pipeline_run(tmp_path_factory):
    """The adaptive cooling-curve study run from Python (a command model: cooling_model.py)."""
    if shutil.which("python3") is None:
        pytest.skip("the cooling model needs python3")
    tmp_path = tmp_path_factory.mktemp("py")
    folder = copy_cooling(tmp_path, "cooling")
    study = iuq.Study.load(folder / "cooling-curve.toml")
    lines = []
    result = study.run(tmp_path / "report", progress=lines.append)
    return study, result, lines, tmp_path


def test_the_pipeline_runs_the_adaptive_engine_and_writes_the_report(pipeline_run):
    study, result, lines, tmp_path = pipeline_run
    assert study.name == "cooling-curve" and study.parameters == ["k", "T0"]
    assert result.report is not None and result.report.is_file()
    assert result.report.parent == tmp_path / "report"
    assert result.adaptive is not None and result.rounds == len(result.adaptive["rounds"]) >= 1
    assert result.runs > 8 and result.failed >= 0
    assert result.q2.shape == (8,)
    assert any(line.startswith("pipeline: ") for line in lines)
    assert "basis" in " ".join(lines)


def test_the_outcome_equals_the_cli(pipeline_run, cli, tmp_path):
    _, result, _, _ = pipeline_run
    folder = copy_cooling(tmp_path, "cooling")
    expected = cli("pipeline", folder / "cooling-curve.toml", "--out", tmp_path / "report")
    for key in ("runs", "failed", "converged", "rounds", "posterior", "adaptive", "q2"):
        assert without_timings(result.raw[key]) == without_timings(expected[key]), key


def test_status_and_export_read_the_campaign(pipeline_run, tmp_path):
    study, result, _, _ = pipeline_run
    status = study.status()
    assert status.total == status.counts["succeeded"] + status.counts["failed"]
    assert status.total >= result.runs - result.failed
    # Every run belongs to a design (the initial one, each adaptive round's, the check's).
    labels = [d["label"] for d in status.designs]
    assert "adaptive-round-1" in labels and len(labels) == len(set(d["id"] for d in status.designs))
    assert sum(d["counts"]["succeeded"] + d["counts"]["failed"] for d in status.designs) >= status.total
    assert all(d["counts"]["pending"] == 0 for d in status.designs)
    rows = study.export()
    assert len(rows) == status.total
    assert {"k", "T0"} <= set(rows[0])
    assert study.export(tmp_path / "runs.csv") == status.total
    assert (tmp_path / "runs.csv").read_text().count("\n") == status.total + 1
    assert study.export(tmp_path / "runs.json") == status.total


def test_a_bad_study_is_a_value_error_naming_the_file_and_key(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('name = "bad"\n[parameters]\nk = { uniform = [1, 0] }\n')
    with pytest.raises(ValueError, match="bad.toml"):
        iuq.Study.load(path)
    with pytest.raises(ValueError, match="cannot read"):
        iuq.Study.load(tmp_path / "missing.toml")


def test_an_exception_of_the_progress_callable_is_raised(pipeline_run, tmp_path):
    study, _, _, _ = pipeline_run

    def progress(line):
        raise KeyError("progress display closed")

    with pytest.raises(KeyError, match="progress display closed"):
        study.run(tmp_path / "again", progress=progress)


def test_bad_run_options_are_value_errors(pipeline_run, tmp_path):
    study, _, _, _ = pipeline_run
    with pytest.raises(ValueError, match="^max_parallel: must be at least 1"):
        study.run(tmp_path / "x", max_parallel=0)
    with pytest.raises(ValueError, match="^format: `xml` is not one of csv, json"):
        study.export(tmp_path / "runs.xml", format="xml")


def test_study_sobol_equals_iuq_sobol(cli):
    path = REPO / "examples" / "ishigami.toml"
    expected = cli("sobol", path, "--n", 512, "--seed", 5)["outputs"]
    ours = iuq.Study.load(path).sobol(n=512, seed=5)
    for j, output in enumerate(ours.outputs):
        s1 = ours.S1 if len(ours.outputs) == 1 else ours.S1[j]
        st = ours.ST if len(ours.outputs) == 1 else ours.ST[j]
        assert list(s1) == [expected[output]["S1"][k] for k in ours.names]
        assert list(st) == [expected[output]["ST"][k] for k in ours.names]


def test_study_basis_equals_iuq_basis(cli, tmp_path):
    folder = copy_cooling(tmp_path, "cooling")
    path = folder / "cooling-exact.toml"
    summary = cli("basis", path, "--samples", 400, "--seed", 3, "--out", tmp_path / "cli")
    ours = iuq.Study.load(path).basis(tmp_path / "py", samples=400, seed=3)
    assert ours.log_evidence == summary["log_evidence"]
    assert ours.n_stages == summary["stages"]
    assert list(ours.mean) == [summary["mean"][k] for k in ours.names]
    assert (tmp_path / "py" / "samples.csv").read_bytes() == (tmp_path / "cli" / "samples.csv").read_bytes()


def test_the_model_posterior_from_python_equals_the_cli(tmp_path, cli):
    """`Study.run(model_posterior=True)` gives the model posterior the CLI gives, certified."""
    study_file = _expression_cooling(tmp_path, "samples = 100\nseed = 2\n")
    study = iuq.Study.load(study_file)
    result = study.run(tmp_path / "py", model_posterior=True)
    m = result.model_posterior
    # 100 members first, grown where their means' Monte Carlo error exceeds `target_mcse`.
    assert m is not None and m["member_sizing"][0]["samples"] == 100
    n = m["samples"]
    assert n == m["member_sizing"][-1]["samples"] >= 100
    # Certified as the method defines it: k̂ under its threshold, or weights so nearly equal
    # (CV <= 0.1, i.e. ESS/N >= 1/1.01) that k̂ of their flat tail says nothing.
    assert m["certified"]
    nearly_equal = m["effective_sample_size"] >= m["samples"] / (1 + 0.1**2)
    assert m["pareto_k"] <= m["pareto_k_threshold"] or nearly_equal, m
    assert set(m["mean"]) == {"k", "T0"}
    expected = cli("pipeline", study_file, "--model-posterior", "--out", tmp_path / "cli")
    assert without_timings(result.raw["model_posterior"]) == without_timings(expected["model_posterior"])
    # The members as arrays: their weighted moments are the summary's (the same numbers, summed
    # in another order), or, where the summary pairs them with the surrogate's samples, within
    # 4 of the members' own error (std/√n on a mean, std/√(2n) on a std) of it.
    members = result.model_posterior_samples
    assert members is not None and members.names == ["k", "T0"]
    assert members.samples.shape == (n, 2) and abs(members.weights.sum() - 1) < 1e-12
    for k, name in enumerate(members.names):
        if m["paired"]:
            assert abs(members.mean[k] - m["mean"][name]) < 4 * members.std[k] / np.sqrt(n), name
            assert abs(members.std[k] / m["std"][name] - 1) < 4 / np.sqrt(2 * n), name
        else:
            assert members.mean[k] == pytest.approx(m["mean"][name], rel=1e-12)
            assert members.std[k] == pytest.approx(m["std"][name], rel=1e-9)


def _expression_cooling(tmp_path, model_posterior_section):
    """The cooling study per time with its program replaced by the same curve in-process."""
    folder = copy_cooling(tmp_path, "cooling")
    text = (folder / "cooling-per-time.toml").read_text()
    program = ('kind = "command"\ncommand = ["./cooling_model.py"]\nabscissa = "t"\noutputs = ["T"]\n'
               'output = { file = "result.json", format = "json" }')
    assert program in text
    expression = 'kind = "expression"\nabscissa = "t"\noutputs = { T = "20 + (T0 - 20) * exp(-k * t)" }'
    study_file = folder / "expression.toml"
    study_file.write_text(text.replace(program, expression) + "\n[model_posterior]\n" + model_posterior_section)
    return study_file


def test_a_bad_model_posterior_key_is_a_value_error_naming_file_and_key(tmp_path):
    """`Study.run(model_posterior=True)` refuses a bad `[model_posterior]` key before any run,
    as the CLI's exit 2 does: the message names the file and the whole key."""
    study_file = _expression_cooling(tmp_path, "samples = 100\nsampels = 3\n")
    study = iuq.Study.load(study_file)
    with pytest.raises(ValueError, match=r"expression\.toml.*model_posterior\.sampels"):
        study.run(tmp_path / "out", model_posterior=True)
    study_file = _expression_cooling(tmp_path / "b", "samples = 3\n")
    with pytest.raises(ValueError, match=r"model_posterior\.samples"):
        iuq.Study.load(study_file).run(tmp_path / "out-b", model_posterior=True)
    # Nothing was run or written: the keys are checked before the surrogate's first run.
    assert not (tmp_path / "out").exists() and not (tmp_path / "out-b").exists()


def test_plain_basis_on_the_model_from_python_gives_a_second_posterior_and_no_weights(tmp_path):
    """`method = "basis"` keeps plain BASIS on the model: a posterior of source "model" beside
    the surrogate's, and neither the reweighted summary nor its members."""
    study_file = _expression_cooling(tmp_path, 'method = "basis"\n[model_sampler]\nsamples = 300\nseed = 2\n')
    result = iuq.Study.load(study_file).run(tmp_path / "py", model_posterior=True)
    assert result.model_posterior is None
    assert result.model_posterior_samples is None
    sources = [p["source"] for p in result.posterior]
    assert sources[1:] == ["model"], sources
    assert (tmp_path / "py" / "basis-model" / "summary.json").is_file()


STUDY_FOR_INTERRUPT = '''
name = "interrupted"
[parameters]
a = { uniform = [0.5, 4.0] }
k = { uniform = [0.05, 0.8] }
[likelihood]
data = { file = "data.csv", x = "x", y = "y", y_err = "e" }
modelling_error = false
[model]
kind = "expression"
abscissa = "x"
outputs = { y = "a * exp(-k * x)" }
[surrogate]
design = { kind = "lhs", n = 6, seed = 1 }
adaptive = { batch = 1, max_runs = 200, tolerance = 0.01 }
[sampler]
samples = 200000
'''

INTERRUPT_SCRIPT = '''
import sys
import iuq
iuq.Study.load(sys.argv[1]).run(sys.argv[2])
'''


def test_ctrl_c_stops_a_study_run_at_its_next_check(tmp_path):
    """Study.run looks for a Ctrl-C between model runs, sampler stages and rounds; a GP-bank
    fit or a sampler stage under way finishes first (under a second here)."""
    import math
    import signal
    import subprocess
    import sys
    import time

    lines = ["x,y,e"] + [f"{x},{2.0 * math.exp(-0.3 * x):.6f},0.05" for x in (0.5, 1, 2, 3, 4, 6, 8)]
    (tmp_path / "data.csv").write_text("\n".join(lines) + "\n")
    (tmp_path / "s.toml").write_text(STUDY_FOR_INTERRUPT)
    (tmp_path / "run.py").write_text(INTERRUPT_SCRIPT)
    process = subprocess.Popen(
        [sys.executable, str(tmp_path / "run.py"), str(tmp_path / "s.toml"), str(tmp_path / "out")],
        stderr=subprocess.PIPE, text=True,
    )
    # Wait until the adaptive rounds are under way.
    deadline = time.time() + 120
    while not (tmp_path / "out" / "adaptive" / "round-2").exists() and process.poll() is None and time.time() < deadline:
        time.sleep(0.05)
    assert process.poll() is None, "the study ended before it could be interrupted"
    sent = time.time()
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    elapsed = time.time() - sent
    assert "KeyboardInterrupt" in stderr, stderr[-2000:]
    assert elapsed < 3.0, f"took {elapsed:.2f} s to stop"
