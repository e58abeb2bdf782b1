"""What SciPy says of the paired cases tests/paired_stats_scipy.rs gives as JSON (argv[1])."""
import json
import sys

from scipy import stats
from scipy.stats import false_discovery_control  # noqa: F401  (SciPy >= 1.11 is required)

cases = json.loads(sys.argv[1])
out = []
for c in cases:
    t = stats.ttest_rel(c["a"], c["b"])
    ci = t.confidence_interval(0.95)
    w = stats.wilcoxon(c["a"], c["b"])
    d = [a - b for a, b in zip(c["a"], c["b"])]
    # The BCa interval of the mean difference, from many resamples so that SciPy's own
    # resampling noise is small beside the tolerance the test allows.
    boot = stats.bootstrap((d,), lambda v, axis: v.mean(axis=axis), n_resamples=200_000,
                           confidence_level=0.95, method="BCa", random_state=0)
    out.append({"t": t.statistic, "t_p": t.pvalue, "ci_low": ci.low, "ci_high": ci.high,
                "w": float(w.statistic), "w_p": float(w.pvalue),
                "bca_low": float(boot.confidence_interval.low),
                "bca_high": float(boot.confidence_interval.high)})
# Holm's step-down adjustment, written out (SciPy has none of its own).
p = [o["w_p"] for o in out]
order = sorted(range(len(p)), key=lambda i: p[i])
holm, running = [0.0] * len(p), 0.0
for k, i in enumerate(order):
    running = max(running, min(1.0, (len(p) - k) * p[i]))
    holm[i] = running
print(json.dumps({"cases": out, "holm": holm}))
