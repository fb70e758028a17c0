#!/usr/bin/python3
"""Where the time of compact's Solve stage goes, from PETSc -log_view output.

    /usr/bin/python3 scripts/log_view_breakdown.py --csv OUT.csv --png OUT.png LABEL=LOG [LABEL=LOG ...]

Each LOG is the standard output of a `compact ... -log_view` run (for instance the log.txt that
scripts/bench_scaling.py writes per run). From the events of the stage "Solve" (maximum time over
the ranks) it forms disjoint parts:
  LU factorization (numeric)     MatLUFactorNum
  LU factorization (symbolic)    MatLUFactorSym
  triangular solves              MatSolve
  Jacobian assembly              SNESJacobianEval - MatSetValuesCOO (elements, contacts with Hessians)
  COO insertion                  MatSetValuesCOO (including the entries sent to other ranks)
  residual evaluation            SNESFunctionEval
  line-search checks             SNESLineSearch - its share of SNESFunctionEval (step limiter, cycle backtracking)
  rest of the Newton solves      SNESSolve - the parts above
  outside the Newton solves      stage - SNESSolve (contact detection, state gathers, pseudo-time control)
and prints, per log, seconds, share of the stage and seconds per Newton iteration (the MatLUFactorNum
count); with two or more logs, the speed-up of every part against the first log.
"""
import argparse
import csv
import re
import sys

PARTS = ["LU factorization (numeric)", "LU factorization (symbolic)", "triangular solves", "Jacobian assembly",
         "COO insertion", "residual evaluation", "line-search checks", "rest of the Newton solves",
         "outside the Newton solves"]


def parse(path, stage="Solve"):
    """{event: (count, max seconds)} of the stage, and the stage's total seconds."""
    events, total, inside = {}, None, False
    with open(path, errors="replace") as f:
        for line in f:
            m = re.match(r"\s*\d+:\s+(\S+):\s+(\S+)", line)
            if m and m.group(1) == stage and total is None:
                total = float(m.group(2))
            if line.startswith("--- Event Stage"):
                inside = line.split(":", 1)[1].strip() == stage
                continue
            if inside:
                cols = line.split()
                if len(cols) > 4 and re.fullmatch(r"[A-Za-z]\w*", cols[0]):
                    try:
                        events[cols[0]] = (int(cols[1]), float(cols[3]))
                    except ValueError:
                        pass
    if total is None or not events:
        sys.exit(f"{path}: no -log_view stage '{stage}' found (run compact with -log_view)")
    return events, total


def breakdown(events, total):
    t = lambda e: events.get(e, (0, 0.0))[1]
    n = lambda e: events.get(e, (0, 0.0))[0]
    fe_per_call = t("SNESFunctionEval") / max(n("SNESFunctionEval"), 1)
    ls_checks = t("SNESLineSearch") - n("SNESLineSearch") * fe_per_call
    parts = [t("MatLUFactorNum"), t("MatLUFactorSym"), t("MatSolve"), t("SNESJacobianEval") - t("MatSetValuesCOO"),
             t("MatSetValuesCOO"), t("SNESFunctionEval"), ls_checks]
    parts.append(t("SNESSolve") - sum(parts))
    parts.append(total - t("SNESSolve"))
    return parts, n("MatLUFactorNum")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("logs", nargs="+", metavar="LABEL=LOG")
    ap.add_argument("--csv")
    ap.add_argument("--png")
    ap.add_argument("--title", default="compact: Solve stage by part (-log_view)")
    a = ap.parse_args()
    runs = []
    for spec in a.logs:
        label, _, path = spec.partition("=")
        if not path:
            sys.exit(f"'{spec}': give LABEL=LOG")
        parts, newton = breakdown(*parse(path))
        runs.append((label, path, parts, newton, sum(parts)))
    rows = []
    for label, path, parts, newton, total in runs:
        print(f"{label} ({path}): Solve stage {total:.1f} s, {newton} Newton iterations (factorizations)")
        for k, name in enumerate(PARTS):
            speedup = runs[0][2][k] / parts[k] if parts[k] > 0 and runs[0][2][k] > 0 else None
            print(f"  {name:30s} {parts[k]:9.1f} s {100 * parts[k] / total:5.1f} %"
                  f" {parts[k] / max(newton, 1):8.4f} s/Newton" + (f"  speed-up {speedup:.2f}" if len(runs) > 1 else ""))
            rows.append([label, name, f"{parts[k]:.3f}", f"{parts[k] / total:.4f}", f"{parts[k] / max(newton, 1):.5f}",
                         "" if speedup is None else f"{speedup:.3f}"])
    if a.csv:
        with open(a.csv, "w", newline="") as f:
            f.write(f"# scripts/log_view_breakdown.py {' '.join(a.logs)}\n")
            f.write("# seconds: maximum over the ranks of PETSc's event times in the stage Solve; speedup: against the"
                    " first run\n")
            w = csv.writer(f)
            w.writerow(["run", "part", "seconds", "share", "seconds_per_newton", "speedup"])
            w.writerows(rows)
        print("wrote", a.csv)
    if a.png:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(9, 1.2 + 0.6 * len(runs)))
        for i, (label, _, parts, newton, _) in enumerate(runs):
            left = 0.0
            for k, name in enumerate(PARTS):
                w = parts[k] / max(newton, 1)
                ax.barh(i, w, left=left, color=f"C{k}", label=name if i == 0 else None)
                left += w
        ax.set_yticks(range(len(runs)), [r[0] for r in runs])
        ax.invert_yaxis()
        ax.set_xlabel("seconds per Newton iteration")
        ax.set_title(a.title, fontsize=9)
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
        fig.tight_layout()
        fig.savefig(a.png, dpi=120)
        print("wrote", a.png)


if __name__ == "__main__":
    main()
