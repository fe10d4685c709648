"""SPH-ParVI's verdict (issue 31, item 1): the false-alarm rate of the evidence behind ``converged`` on i.i.d.
samples of the built-in 2D targets, its power on biased samples, and the issue's three cases through the CLI.

    python reproductions/parvi-verdict/run.py --out reproductions/parvi-verdict/results          # ~45 CPU-min
    python reproductions/parvi-verdict/run.py --quick --out /tmp/parvi-verdict                   # ~5 CPU-min

Writes ``OUT/verdict.json``: ``calibration`` (per target: trials, MALA-check, importance-check and mode-search
alarms, any of them),
``power`` (per bias: trials, detections), ``cases`` (per issue case: the CLI's exit code, ``converged``,
``at_rest``, ``check_passed``, the MALA check's ``max_t`` and ``bound``, the importance check's ``max_t``,
``p_value`` and ``ess``, the modes missed, whether it restarted, the samples' mean and
covariance against the truth).
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path[:0] = [str(ROOT), str(HERE)]

import issue_targets  # noqa: E402
from ase_sphrelax.sampling import get_target  # noqa: E402
from ase_sphrelax.sampling.result import CountingTarget  # noqa: E402
from ase_sphrelax.sampling.verdict import VERDICT_ALPHA, _evidence  # noqa: E402

TARGETS = ("gaussian", "correlated", "banana", "ring8", "donut", "funnel")


def calibration(trials, m):
    """The evidence (MALA check, importance check and mode search) on ``trials`` i.i.d. samples of M points of each
    built-in 2D target: every alarm is a false alarm. Also the evaluations the checks cost per trial."""
    out = {}
    for index, name in enumerate(TARGETS):  # seeds per target: gaussian and correlated are affine images
        target = get_target(name)
        rng = np.random.default_rng([1, trials, index])
        mala_alarms = is_alarms = is_inconclusive = mode_alarms = either = 0
        max_t, is_t, density, score = [], [], 0, 0
        for trial in range(trials):
            x = target.sample(m, rng)
            probe = CountingTarget(target.log_density, target.score, 2)
            mala, importance, modes = _evidence(x, probe, np.random.default_rng([trial, 31, index]), [np.zeros(2)])
            mala_alarms += not mala["passed"]
            is_alarms += not importance["passed"]
            is_inconclusive += not importance.get("conclusive", False)
            mode_alarms += bool(modes["missed"])
            either += (not mala["passed"]) or (not importance["passed"]) or bool(modes["missed"])
            max_t.append(mala.get("max_t", np.nan))
            is_t.append(importance.get("max_t") if importance.get("max_t") is not None else np.nan)
            density, score = density + probe.n_density, score + probe.n_score
        out[name] = dict(trials=trials, m=m, mala_alarms=mala_alarms, importance_alarms=is_alarms,
                         importance_inconclusive=is_inconclusive, mode_alarms=mode_alarms, alarms=either,
                         rate=either / trials, median_max_t=float(np.nanmedian(max_t)),
                         median_importance_t=float(np.nanmedian(is_t)), density_per_trial=density / trials,
                         score_per_trial=score / trials)
        print(name, out[name], flush=True)
    total = sum(v["trials"] for v in out.values())
    alarms = sum(v["alarms"] for v in out.values())
    return dict(per_target=out, trials=total, alarms=alarms, rate=alarms / total,
                mala_rate=sum(v["mala_alarms"] for v in out.values()) / total,
                importance_rate=sum(v["importance_alarms"] for v in out.values()) / total,
                importance_inconclusive=sum(v["importance_inconclusive"] for v in out.values()),
                mode_rate=sum(v["mode_alarms"] for v in out.values()) / total, nominal=VERDICT_ALPHA)


def power(trials, m):
    """Detections of biased samples of the correlated Gaussian (variance 1.2^2 and 1.3^2 times, mean 0.3 sd off)."""
    target = get_target("correlated")
    out = {}
    for label, bias in (("sd x1.2", lambda x: 1.2 * x), ("sd x1.3", lambda x: 1.3 * x),
                        ("mean +0.3 sd", lambda x: x + np.array([0.3, 0.0]))):
        rng = np.random.default_rng([2, trials])
        hits = 0
        for trial in range(trials):
            probe = CountingTarget(target.log_density, target.score, 2)
            mala, importance, modes = _evidence(bias(target.sample(m, rng)), probe,
                                                np.random.default_rng([trial, 32]), [np.zeros(2)])
            hits += (not mala["passed"]) or (not importance["passed"]) or bool(modes["missed"])
        out[label] = dict(trials=trials, m=m, detected=hits, rate=hits / trials)
        print(label, out[label], flush=True)
    return out


def cli_case(name, args, truth_mean, truth_cov, out_root):
    """One issue case through ``sphrelax sample`` (no --steps: the default length, exit 3 when not converged)."""
    out = out_root / name
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), str(HERE), os.environ.get("PYTHONPATH", "")]))
    t0 = time.time()
    proc = subprocess.run([sys.executable, "-m", "ase_sphrelax.cli", "sample", *args, "--out", str(out),
                           "--no-progress"], env=env, capture_output=True, text=True)
    summary = json.loads((out / "summary.json").read_text())
    x = np.load(out / "samples.npy")
    verdict = summary.get("verdict", {})
    mala = verdict.get("mala_check") or {}
    importance = verdict.get("importance_check") or {}
    modes = verdict.get("modes") or {}
    row = dict(command="sphrelax sample " + " ".join(args), exit=proc.returncode, converged=summary["converged"],
               at_rest=summary.get("at_rest"), check_passed=verdict.get("check_passed"),
               mala_passed=mala.get("passed"), mala_max_t=mala.get("max_t"),
               mala_bound=mala.get("bound"), mala_worst=mala.get("worst"), importance_passed=importance.get("passed"),
               importance_max_t=importance.get("max_t"), importance_p=importance.get("p_value"),
               importance_ess=importance.get("ess"), importance_worst=importance.get("worst"),
               n_check_density=summary["parameters"].get("n_check_density"),
               n_check_score=summary["parameters"].get("n_check_score"),
               modes_found=len(modes.get("modes", [])), modes_missed=len(modes.get("missed", [])),
               restarted=verdict.get("restarted") is not None, mean=x.mean(axis=0).tolist(),
               cov=np.cov(x, rowvar=False).tolist(), truth_mean=np.asarray(truth_mean).tolist(),
               truth_cov=np.asarray(truth_cov).tolist(), reason=summary["convergence_reason"],
               stderr_last=proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else "",
               wall=time.time() - t0)
    if verdict.get("restarted"):
        first = verdict["restarted"]["first"]
        row["first_modes_missed"] = len(first["modes"]["missed"])
        row["first_mode_shares"] = [(m["laplace_share"], m["particle_share"]) for m in first["modes"]["modes"]]
    print(name, {k: row[k] for k in ("exit", "converged", "at_rest", "mala_max_t", "importance_max_t", "importance_p",
                                     "modes_missed", "restarted", "mean")}, flush=True)
    return row


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=HERE / "results")
    parser.add_argument("--quick", action="store_true", help="fewer trials and particles")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    trials, m, n = (20, 300, "200") if args.quick else (60, 500, "500")
    runs = Path(tempfile.mkdtemp(prefix="parvi-verdict-"))  # the CLI's outputs; only verdict.json is kept
    t = issue_targets
    cases = {}

    def run_cases():  # the CLI runs (subprocesses) alongside the calibration
        cases["mixture"] = cli_case("mixture", ["--target", "issue_targets:mixture_logp", "--score",
                                                "issue_targets:mixture_score", "--dim", "2", "--n", n],
                                    t.MIXTURE_MEAN, t.MIXTURE_COV, runs)
        cases["other_banana"] = cli_case("other_banana", ["--target", "issue_targets:banana_logp", "--score",
                                                          "issue_targets:banana_score", "--dim", "2", "--n", n],
                                         t.BANANA_MEAN, t.BANANA_COV, runs)
        cases["banana"] = cli_case("banana", ["--target", "banana", "--n", n], [0.0, 0.0],
                                   [[100.0, 0.0], [0.0, 19.0]], runs)

    worker = threading.Thread(target=run_cases)
    worker.start()
    result = dict(quick=args.quick, calibration=calibration(trials, m), power=power(trials * 2 // 3, m))
    worker.join()
    result["cases"] = {k: cases[k] for k in ("mixture", "other_banana", "banana")}
    (args.out / "verdict.json").write_text(json.dumps(result, indent=1))
    print(f"wrote {args.out / 'verdict.json'}")


if __name__ == "__main__":
    main()
