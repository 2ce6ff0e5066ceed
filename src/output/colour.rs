//! The colour scale of mean stress shared by pictures (`render`) and the Foxglove `/scene`.

/// Viridis colour map (matplotlib's default), `t` in [0, 1].
pub fn viridis(t: f64) -> [u8; 3] {
    const STOPS: [[f64; 3]; 9] = [
        [68.0, 1.0, 84.0],
        [72.0, 40.0, 120.0],
        [62.0, 74.0, 137.0],
        [49.0, 104.0, 142.0],
        [38.0, 130.0, 142.0],
        [31.0, 158.0, 137.0],
        [53.0, 183.0, 121.0],
        [109.0, 205.0, 89.0],
        [253.0, 231.0, 37.0],
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = t * (STOPS.len() - 1) as f64;
    let k = (x.floor() as usize).min(STOPS.len() - 2);
    let f = x - k as f64;
    let mut out = [0u8; 3];
    for c in 0..3 {
        out[c] = (STOPS[k][c] + f * (STOPS[k + 1][c] - STOPS[k][c])).round() as u8;
    }
    out
}

/// Colour scale of the grains' mean stress in `/scene` and in rendered pictures: `[0, max]`
/// with `max` the 99th percentile of the frame's positive mean stresses (a few very loaded
/// grains would otherwise flatten the picture).
pub fn stress_colour_max(mean_stresses_c: &[f64]) -> f64 {
    let mut positive: Vec<f64> = mean_stresses_c
        .iter()
        .copied()
        .filter(|s| s.is_finite() && *s > 0.0)
        .collect();
    if positive.is_empty() {
        return 0.0;
    }
    let k = ((positive.len() as f64 * 0.99) as usize).min(positive.len() - 1);
    let (_, v, _) = positive.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    *v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colour_scale_ignores_rattlers_and_outliers() {
        let mut s: Vec<f64> = (1..=1000).map(|k| k as f64).collect();
        s.push(0.0);
        s.push(1e9);
        let top = stress_colour_max(&s);
        assert!((985.0..=1000.0).contains(&top), "{top}");
        assert_eq!(stress_colour_max(&[0.0, -1.0]), 0.0);
    }
}
