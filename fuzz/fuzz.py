"""Coverage-guided fuzzing of every parser with atheris (libFuzzer for Python).

    make fuzz                                   # every target, 1,000,000 inputs each
    .venv/bin/python fuzz/fuzz.py --runs 20000  # a quick look
    .venv/bin/python fuzz/fuzz.py --runs 1000000 vn200 link-signed
    .venv/bin/python fuzz/fuzz.py --one TARGET -- [libFuzzer flags]   # one target, by hand

Each target runs in its own process under libFuzzer with a memory limit (-rss_limit_mb) and a
per-input time limit (-timeout): an exception other than the parser's own typed error, a
contract assertion, an input taking longer than the limit, or memory beyond the limit is a
crash; libFuzzer stops and writes the input to `fuzz/out/TARGET/crash-*` (leak-*, timeout-*,
oom-*), which `--one TARGET -- fuzz/out/TARGET/crash-…` replays. Targets run two at a time (one
per core here). The table at the end gives inputs run, time, inputs per second, the coverage
reached and the peak memory of each target. The corpus each run grows is kept in
`fuzz/out/TARGET/corpus/` and seeds the next run (seeds come from the encoders).
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
OUT = HERE / "out"
# Inputs up to 1 KiB: several frames of every codec (the longest, an AP=2 XBee frame fully
# escaped, is 607 bytes); longer inputs only slow each run.
LIMITS = ["-rss_limit_mb=2048", "-timeout=10", "-max_len=1024", "-print_final_stats=1"]


def run_one(name: str, flags: list[str]) -> None:
    """Inside the child: instrument our modules, then hand the target to libFuzzer."""
    import atheris

    sys.path.insert(0, str(ROOT))
    sys.path.insert(0, str(HERE))
    with atheris.instrument_imports(include=["agent", "drivers", "digi", "targets", "tomllib"]):
        import targets

    target = targets.TARGETS[name]
    atheris.Setup([sys.argv[0], *flags], target)
    atheris.Fuzz()


def campaign(name: str, runs: int) -> dict:
    """One target in a child process; its libFuzzer statistics."""
    sys.path.insert(0, str(HERE))
    sys.path.insert(0, str(ROOT))
    import targets

    out = OUT / name
    corpus = out / "corpus"
    corpus.mkdir(parents=True, exist_ok=True)
    for k, seed in enumerate(targets.seeds(name)):
        (corpus / f"seed-{k}").write_bytes(seed)
    for old in out.glob("*-*"):  # findings of an earlier run: this run's stand alone
        if old.is_file():
            old.unlink()
    log = out / "fuzz.log"
    began = time.monotonic()
    with open(log, "w") as handle:
        code = subprocess.call(
            [
                sys.executable,
                __file__,
                "--one",
                name,
                "--",
                str(corpus),
                f"-runs={runs}",
                f"-artifact_prefix={out}/",
                *LIMITS,
            ],
            stdout=handle,
            stderr=subprocess.STDOUT,
            cwd=ROOT,
        )
    wall = time.monotonic() - began
    (out / "exit").write_text(f"{code} {wall:.1f}\n")
    return summary(name)


def summary(name: str) -> dict:
    """A target's last run, from its log (`--report` prints these without running)."""
    out = OUT / name
    log = out / "fuzz.log"
    code, wall = (out / "exit").read_text().split() if (out / "exit").exists() else (-1, 0)
    code, wall = int(code), float(wall)
    text = log.read_text(errors="replace") if log.exists() else ""
    stat = {k: int(v) for k, v in re.findall(r"stat::(\w+):\s+(\d+)", text)}
    cov = re.findall(r"cov: (\d+) ft: (\d+)", text)
    crashes = sorted(
        p.name
        for p in out.glob("*-*")
        if p.is_file() and p.name[:4] in ("cras", "leak", "time", "oom-", "slow")
    )
    return {
        "target": name,
        "exit": code,
        "runs": stat.get("number_of_executed_units", 0),
        "seconds": wall,
        "per_s": stat.get("average_exec_per_sec", 0),
        "coverage": int(cov[-1][0]) if cov else 0,
        "features": int(cov[-1][1]) if cov else 0,
        "peak_rss_mb": stat.get("peak_rss_mb", 0),
        "findings": crashes,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("targets", nargs="*", help="default: every target")
    parser.add_argument("--runs", type=int, default=1_000_000, help="inputs per target")
    parser.add_argument("--jobs", type=int, default=2, help="targets at a time")
    parser.add_argument("--report", action="store_true", help="the table of the last runs only")
    if sys.argv[1:2] == ["--one"]:  # the child: libFuzzer's own flags follow, untouched
        run_one(sys.argv[2], [a for a in sys.argv[3:] if a != "--"])
        return 0
    args = parser.parse_args()
    sys.path.insert(0, str(HERE))
    sys.path.insert(0, str(ROOT))
    import targets

    names = args.targets or list(targets.TARGETS)
    unknown = set(names) - set(targets.TARGETS)
    if unknown:
        parser.error(f"unknown targets {sorted(unknown)}; known: {list(targets.TARGETS)}")
    if args.report:
        results = [summary(n) for n in names]
    else:
        with ThreadPoolExecutor(args.jobs) as pool:
            results = list(pool.map(lambda n: campaign(n, args.runs), names))
    print(
        f"{'target':<13} {'inputs':>10} {'time s':>8} {'inputs/s':>9} {'cov':>6} {'ft':>6} "
        f"{'peak MB':>8}  result"
    )
    failed = False
    for r in results:
        ok = r["exit"] == 0 and not r["findings"] and r["runs"] >= (0 if args.report else args.runs)
        failed |= not ok
        verdict = "ok" if ok else f"FAILED (exit {r['exit']}; {', '.join(r['findings'])})"
        print(
            f"{r['target']:<13} {r['runs']:>10} {r['seconds']:>8.0f} {r['per_s']:>9} "
            f"{r['coverage']:>6} {r['features']:>6} {r['peak_rss_mb']:>8}  {verdict}"
        )
    print(f"logs and findings: {OUT}/TARGET/")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
