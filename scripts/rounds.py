"""Warm times in alternating rounds, for the benchmark scripts beside
Mitsuba (bench_vs_mitsuba.py, bench_grad_vs_mitsuba.py): on a shared
machine whose speed drifts between minutes, the two sides are compared
round by round, each round timing one side and then the other."""
import statistics


def alternate(ours, theirs, first, rounds):
    """Adds `rounds - 1` rounds of `ours()` then `theirs()` (each returns a
    result dict with 'warm_median_s') to the `first` pair of results, and
    writes into those two dicts the medians of their warm times over the
    rounds, and into `theirs`'s one 'warm_ratio': the median of the rounds'
    ratios theirs / ours with their smallest and largest."""
    o0, t0 = first
    warm = [(o0['warm_median_s'], t0['warm_median_s'])]
    for _ in range(rounds - 1):
        warm.append((ours()['warm_median_s'], theirs()['warm_median_s']))
    ratios = sorted(t / o for o, t in warm)
    o0['warm_median_s'] = statistics.median(o for o, _ in warm)
    t0['warm_median_s'] = statistics.median(t for _, t in warm)
    t0['warm_ratio'] = (statistics.median(ratios), ratios[0], ratios[-1])
    return ratios
