//! Comparing two curves of (image error, frame time) — ours and a baseline's, each swept over its
//! settings — at matched error, as the forest benchmark reports them.

/// The points of a (rmse, ms) curve that no other point beats on both: sorted by RMSE, each
/// faster than every point of lower RMSE.
pub fn lower_envelope(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut sorted: Vec<(f64, f64)> = points.to_vec();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let mut out: Vec<(f64, f64)> = Vec::new();
    for p in sorted {
        if out.last().is_none_or(|last| p.1 < last.1) {
            out.push(p);
        }
    }
    out
}

/// Frame time on an envelope at `rmse`, linearly interpolated; `None` outside its range.
pub fn interpolate(envelope: &[(f64, f64)], rmse: f64) -> Option<f64> {
    let first = envelope.first()?;
    let last = envelope.last()?;
    if rmse < first.0 || rmse > last.0 {
        return None;
    }
    for w in envelope.windows(2) {
        let (a, b) = (w[0], w[1]);
        if rmse >= a.0 && rmse <= b.0 {
            let t = if b.0 > a.0 {
                (rmse - a.0) / (b.0 - a.0)
            } else {
                0.0
            };
            return Some(a.1 + t * (b.1 - a.1));
        }
    }
    Some(first.1)
}

/// Our speed-up at each of our envelope points the baseline's envelope reaches.
pub fn matched_speedups(ours: &[(f64, f64)], baseline: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let (ours, baseline) = (lower_envelope(ours), lower_envelope(baseline));
    ours.iter()
        .filter_map(|&(rmse, ms)| interpolate(&baseline, rmse).map(|b| (rmse, b / ms.max(1e-9))))
        .collect()
}

/// At each point of the baseline's envelope, our fastest frame at equal or better RMSE, as a
/// speed-up (`None` where none of our points is as good).
pub fn speedups_at_baseline_points(
    ours: &[(f64, f64)],
    baseline: &[(f64, f64)],
) -> Vec<(f64, Option<f64>)> {
    lower_envelope(baseline)
        .iter()
        .map(|&(rmse, ms)| {
            let best = ours
                .iter()
                .filter(|o| o.0 <= rmse)
                .map(|o| o.1)
                .min_by(f64::total_cmp);
            (rmse, best.map(|b| ms / b.max(1e-9)))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matched_speedup_interpolates_on_the_baseline_envelope() {
        // Baseline: 0.02 → 100 ms, 0.04 → 50 ms (and a dominated point).
        let baseline = [(0.02, 100.0), (0.04, 50.0), (0.05, 80.0)];
        let ours = [(0.03, 25.0), (0.01, 200.0)];
        let m = matched_speedups(&ours, &baseline);
        // 0.03 sits halfway: the baseline would take 75 ms.
        assert_eq!(m.len(), 1);
        assert!((m[0].1 - 3.0).abs() < 1e-9);
        assert_eq!(lower_envelope(&baseline).len(), 2);
        // At the baseline's points: our fastest at equal or better error (0.01 → 200 ms).
        let at = speedups_at_baseline_points(&ours, &baseline);
        assert_eq!(at, vec![(0.02, Some(0.5)), (0.04, Some(2.0))]);
    }
}
