"""Choose the GP maps' defaults on the tuning seeds of the 2D scene family.

Every candidate setting of GPOMIK, GPOM and the mixture of experts is fitted
and scored (ROC AUC and FPR at TPR 0.9 against exact truth on the 0.1 m grid,
times with variances) on :data:`occgp.datasets.TUNING_SEEDS` only, through
:func:`occgp.evaluation.evaluate_scene_set`; the test seeds play no part.
Groups of candidates vary one choice at a time around the defaults:

* ``gpomik``: the hyper-parameter objective (log marginal likelihood or
  leave-one-out);
* ``gpom``: the objective;
* ``mixture``: the clustering (line tracking or Dirichlet process), the
  merging rule, the fewest observations of an expert (``min_size``), the
  line tracker's gap, the DP's covariance prior and the objective.

Run: ``PYTHONPATH=bench python bench/tune_gp.py --group mixture --out m.json``;
``--summary FILE ...`` prints the tables of saved records (mean, std and
worst AUC per candidate, and per scene kind).
"""

from __future__ import annotations

import argparse
import json

from occgp.datasets import TEST_SEEDS, TUNING_SEEDS
from occgp.evaluation import evaluate_scene_set, format_scene_set
from occgp.gp import GPOM, GPOMIK, DirichletProcessClustering, GPMixture, LineTracking


def candidates(group):
    """Name -> factory of the candidates of `group`."""
    if group == "gpomik":
        return {
            "GPOMIK lml": lambda: GPOMIK(random_state=0),
            "GPOMIK loo": lambda: GPOMIK(objective="loo", random_state=0),
        }
    if group == "gpom":
        return {
            "GPOM lml": lambda: GPOM(random_state=0),
            "GPOM loo": lambda: GPOM(objective="loo", random_state=0),
        }
    if group == "mixture":
        def mix(**kw):
            return lambda: GPMixture(random_state=0, **kw)
        return {
            "mixture LT": mix(),
            "mixture LT rbcm": mix(combine="rbcm"),
            "mixture LT gap=1": mix(clustering=LineTracking(gap_threshold=1.0)),
            "mixture DP": mix(clustering="dp"),
            "mixture DP rbcm": mix(clustering="dp", combine="rbcm"),
            "mixture DP bcm": mix(clustering="dp", combine="bcm"),
            "mixture DP min_size=50": mix(clustering="dp", min_size=50),
            "mixture DP prior=1": mix(clustering=DirichletProcessClustering(
                covariance_prior=1.0)),
            "mixture DP loo": mix(clustering="dp", expert=GPOMIK(n_restarts=0,
                                                                 objective="loo")),
            "mixture DP min_size=300": mix(clustering="dp", min_size=300),
            "mixture DP min_size=600": mix(clustering="dp", min_size=600),
            "mixture DP min_size=600 max=2000": mix(clustering="dp", min_size=600,
                                                    max_cluster_size=2000),
            "mixture LT min_size=300": mix(min_size=300),
            "mixture LT min_size=600": mix(min_size=600),
            "mixture LT global": mix(hyperparameters="global"),
            "mixture LT global minvar": mix(hyperparameters="global", combine="minvar"),
            "mixture LT global rbcm": mix(hyperparameters="global", combine="rbcm"),
            "mixture LT global loo": mix(hyperparameters="global", expert=GPOMIK(
                n_restarts=0, objective="loo")),
            "mixture DP global": mix(clustering="dp", hyperparameters="global"),
            "mixture DP global minvar": mix(clustering="dp", hyperparameters="global",
                                            combine="minvar"),
        }
    raise ValueError(f"unknown group {group!r}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--group", choices=["gpomik", "gpom", "mixture"])
    parser.add_argument("--only", nargs="*", default=None, help="candidate names to run")
    parser.add_argument("--seeds", choices=["tuning", "test"], default="tuning")
    parser.add_argument("--out", default=None, help="JSON file the records are added to")
    parser.add_argument("--summary", nargs="*", default=None, help="print saved records")
    args = parser.parse_args()
    if args.summary is not None:
        records = [r for path in args.summary for r in json.load(open(path))]
        print(format_scene_set(records))
        print(format_scene_set(records, by_kind=True))
        return
    methods = candidates(args.group)
    if args.only:
        methods = {k: v for k, v in methods.items() if k in args.only}
    seeds = TUNING_SEEDS if args.seeds == "tuning" else TEST_SEEDS
    records = []
    for seed in seeds:  # seed by seed, so that a long run saves what it has
        records += evaluate_scene_set(methods, [seed])
        for r in records[-len(methods):]:
            print(f"{r['method']:32s} seed {r['seed']:4d} {r['kind']:10s} AUC {r['auc']:.4f} "
                  f"FPR {r['fpr']:.3f} {r['seconds']:6.1f} s", flush=True)
        if args.out:
            with open(args.out, "w") as f:
                json.dump(records, f)
    print(format_scene_set(records))


if __name__ == "__main__":
    main()
