"""The posing suite's verdicts and report (scripts/posing_suite.py runs
the edits and documents the rules in its docstring): the PASS rules
against libigl ARAP's pose and a preset's own figures, and the tables the
suite prints. Standard library only.
"""
import math

# a character edit settles each step within this many iterations
MAX_ITERS_PER_STEP = 30
# meshes of this many vertices or more must settle 5x sooner than ARAP, below 3x
SETTLE_LARGE = 5000
# a shape measure judged against ARAP's: (key, "higher" or "lower" is better)
SHAPE_MEASURES = {"bar": [("min_area", "higher"), ("twist_dev_deg", "lower")],
                  "bend": [("bend_cv", "lower")]}
TWIST_135 = {"min_area": (">=", 0.92), "twist_dev_deg": ("<=", 3.0)}
# the paper's figures a preset is held to, on top of the rules against ARAP
PRESET_RULES = {
    "elastica": {
        "bar-135": TWIST_135,
        "bar-300": {"min_area": (">=", 0.8), "twist_dev_deg": ("<=", 45.0)},
        "survey-bar": TWIST_135,
        "cylinder-120": {"bend_cv": ("<=", 0.1)},
        "cylinder-180": {"bend_cv": ("<=", 0.1)},
        "bar-bend-120": {"bend_cv": ("<=", 0.1)},
        "bar-bend-180": {"bend_cv": ("<=", 0.1)},
    },
}


def objective_failures(o):
    """The rules on our objective alone: it never grows, no edit diverged."""
    fails = []
    if o["monotone"] is not True:
        fails.append("objective not monotone" if o["monotone"] is False else "no objectives")
    if o["diverged"] is not False:
        fails.append(f"diverged {o['diverged']}")
    return fails


def judge(row):
    """Fills row["failures"] and row["verdict"] (PASS / FAIL / ERROR) by the
    rules of scripts/posing_suite.py's docstring."""
    if row.get("error"):
        row["verdict"] = "ERROR"
        return
    o, a, fails = row["ours"], row["arap"], []
    o["distortion"]["mean_ratio"] = rm = o["distortion"]["mean"] / a["distortion"]["mean"]
    o["distortion"]["max_ratio"] = rx = o["distortion"]["max"] / a["distortion"]["max"]
    row["settle_ratio"] = a["settle_ms"] / o["settle_ms"] if o["settle_ms"] else float("nan")
    need = 5.0 if row["vertices"] >= SETTLE_LARGE else 3.0
    if not row["settle_ratio"] >= need:
        fails.append(f"settle only x{row['settle_ratio']:.1f} faster than ARAP (need x{need:g})")
    shape = row.get("kind") in SHAPE_MEASURES
    for k, s in enumerate(o["steps"], 1):
        if not s.get("converged"):
            fails.append(f"step {k}: not converged in {s.get('iterations')} it")
        elif not shape and not (s.get("iterations") or 0) <= MAX_ITERS_PER_STEP:
            fails.append(f"step {k}: {s.get('iterations')} it > {MAX_ITERS_PER_STEP}")
    fails += objective_failures(o)
    if shape:
        om, am = o["measure"], a["measure"]
        for key, better in SHAPE_MEASURES[row["kind"]]:
            x, y = om.get(key, float("nan")), am.get(key, float("nan"))
            if not (x >= y if better == "higher" else x <= y):
                fails.append(f"{key} {x:.3g} worse than ARAP's {y:.3g}")
    else:
        if not rm <= 1.5:
            fails.append(f"mean distortion x{rm:.2f} ARAP")
        if not rx <= 2.0:
            fails.append(f"max distortion x{rx:.2f} ARAP")
    for key, (op, lim) in row["rules"].items():
        x = o["measure"].get(key, float("nan"))
        if not (x >= lim if op == ">=" else x <= lim):
            fails.append(f"{key} {x:.3g} (need {op} {lim})")
    row["failures"] = fails
    row["verdict"] = "PASS" if not fails else "FAIL"


def judge_objective(row):
    """`--no-arap`'s verdict: only the rules on our objective (it never
    grows, no edit diverged) and that the run completed."""
    if row.get("error"):
        row["verdict"] = "ERROR"
        return
    fails = objective_failures(row["ours"])
    row["failures"] = fails
    row["verdict"] = "PASS" if not fails else "FAIL"


def fmt(x, spec=".3g"):
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    if isinstance(x, bool):
        return "yes" if x else "no"
    return format(x, spec)


def figures(o, a):
    om, am = o.get("measure", {}), a.get("measure", {})
    if "min_area" in om or "min_area" in am:
        return (f"area {fmt(om.get('min_area'))}/{fmt(am.get('min_area'))}, "
                f"dev {fmt(om.get('twist_dev_deg'), '.1f')}/{fmt(am.get('twist_dev_deg'), '.1f')}°")
    if "bend_cv" in om or "bend_cv" in am:
        return f"CV {fmt(om.get('bend_cv'))}/{fmt(am.get('bend_cv'))}"
    return ""


def print_table(rows):
    print("| case | V | steps | ours it | conv | objective first→last | mono | ours dist mean/max "
          "| ours ms/it | ours settle ms | ARAP it | conv | ARAP dist mean/max | ARAP ms/it "
          "| ARAP settle ms | mean÷ | max÷ | settle ARAP÷ours | figures ours/ARAP | verdict |")
    print("|" + "---|" * 20)
    for r in rows:
        o, a = r.get("ours", {}), r.get("arap", {})
        od, ad = o.get("distortion", {}), a.get("distortion", {})
        verdict = r["verdict"]
        if r.get("error"):
            verdict += ": " + r["error"]
        elif r.get("failures"):
            verdict += ": " + "; ".join(r["failures"])
        print(f"| {r['case']} | {r.get('vertices', '-')} | {r.get('steps', '-')} "
              f"| {fmt(o.get('iterations'), 'd')} | {fmt(o.get('converged'))} "
              f"| {fmt(o.get('objective_first'))}→{fmt(o.get('objective_last'))} "
              f"| {fmt(o.get('monotone'))} | {fmt(od.get('mean'))}/{fmt(od.get('max'))} "
              f"| {fmt(o.get('iteration_ms'), '.1f')} | {fmt(o.get('settle_ms'), '.0f')} "
              f"| {fmt(a.get('iterations'), 'd')} | {fmt(a.get('converged'))} "
              f"| {fmt(ad.get('mean'))}/{fmt(ad.get('max'))} | {fmt(a.get('iteration_ms'), '.1f')} "
              f"| {fmt(a.get('settle_ms'), '.0f')} | {fmt(od.get('mean_ratio'), '.2f')} "
              f"| {fmt(od.get('max_ratio'), '.2f')} | {fmt(r.get('settle_ratio'), '.2f')} "
              f"| {figures(o, a)} | {verdict} |")
    even = [r for r in rows if "even" in r]
    if even:
        print("\nThe even pose (`even_pose`: every cross-section kept, the twist or bend "
              "spread evenly, the handle on its target): what the area, twist and bend "
              "rules cost in edge distortion.\n")
        print("| case | even dist mean/max | even mean ÷ ARAP | ours mean ÷ ARAP "
              "| figures even/ours/ARAP |")
        print("|" + "---|" * 5)
        for r in even:
            e, o, a = r["even"], r.get("ours", {}), r.get("arap", {})
            ed, ad = e["distortion"], a.get("distortion", {})
            ratio = ed["mean"] / ad["mean"] if ad.get("mean") else float("nan")
            em, om, am = e.get("measure", {}), o.get("measure", {}), a.get("measure", {})
            if "bend_cv" in em:
                fig = (f"CV {fmt(em.get('bend_cv'))}/{fmt(om.get('bend_cv'))}"
                       f"/{fmt(am.get('bend_cv'))}")
            else:
                fig = (f"area {fmt(em.get('min_area'))}/{fmt(om.get('min_area'))}"
                       f"/{fmt(am.get('min_area'))}, dev "
                       f"{fmt(em.get('twist_dev_deg'), '.1f')}/{fmt(om.get('twist_dev_deg'), '.1f')}"
                       f"/{fmt(am.get('twist_dev_deg'), '.1f')}°")
            print(f"| {r['case']} | {fmt(ed['mean'])}/{fmt(ed['max'])} | {fmt(ratio, '.2f')} "
                  f"| {fmt(o.get('distortion', {}).get('mean_ratio'), '.2f')} | {fig} |")
