//! Summary statistics for the experiments: mean ± standard error, and Welch's two-sample t-test.
//!
//! The Student t distribution's CDF is computed from the regularized incomplete beta function,
//! `P(|T| > t) = I_{ν/(ν+t²)}(ν/2, 1/2)`, evaluated with the continued fraction of Numerical Recipes §6.4
//! (modified Lentz) and `ln Γ` by the Lanczos approximation (g = 7, 9 terms). Everything is pure `f64`.

use serde::{Deserialize, Serialize};

/// Mean, sample standard deviation and standard error of a sample.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Describe {
    /// Sample size.
    pub n: usize,
    /// Arithmetic mean (NaN for an empty sample).
    pub mean: f64,
    /// Sample standard deviation with n − 1 in the denominator (0 for n < 2).
    pub sd: f64,
    /// Standard error of the mean, sd / √n (0 for n < 2).
    pub se: f64,
}

/// Describes `xs`.
pub fn describe(xs: &[f64]) -> Describe {
    let n = xs.len();
    if n == 0 {
        return Describe {
            n,
            mean: f64::NAN,
            sd: 0.0,
            se: 0.0,
        };
    }
    let mean = xs.iter().sum::<f64>() / n as f64;
    let sd = if n < 2 {
        0.0
    } else {
        let ss: f64 = xs.iter().map(|x| (x - mean) * (x - mean)).sum();
        (ss / (n - 1) as f64).sqrt()
    };
    Describe {
        n,
        mean,
        sd,
        se: sd / (n as f64).sqrt(),
    }
}

/// The outcome of Welch's unequal-variance t-test of `b` against `a`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WelchTest {
    /// t = (mean_b − mean_a) / √(s_a²/n_a + s_b²/n_b).
    pub t: f64,
    /// Welch–Satterthwaite degrees of freedom.
    pub df: f64,
    /// Two-sided p-value.
    pub p: f64,
}

impl WelchTest {
    /// The p-value as a table prints it: three decimals, and `< 0.001` below that (never `0.000`).
    pub fn p_text(&self) -> String {
        format_p(self.p)
    }
}

/// A p-value to three decimals, `< 0.001` below that (a p-value is never zero), `–` when not finite.
pub fn format_p(p: f64) -> String {
    if !p.is_finite() {
        "–".into()
    } else if p < 0.001 {
        "< 0.001".into()
    } else {
        format!("{p:.3}")
    }
}

/// Welch's t-test comparing sample `b` with sample `a`; `None` when either has fewer than two values or
/// both have zero variance.
pub fn welch(a: &[f64], b: &[f64]) -> Option<WelchTest> {
    let (da, db) = (describe(a), describe(b));
    if da.n < 2 || db.n < 2 {
        return None;
    }
    let va = da.sd * da.sd / da.n as f64;
    let vb = db.sd * db.sd / db.n as f64;
    let v = va + vb;
    if v <= 0.0 || !v.is_finite() {
        return None;
    }
    let t = (db.mean - da.mean) / v.sqrt();
    let df = v * v / (va * va / (da.n - 1) as f64 + vb * vb / (db.n - 1) as f64);
    Some(WelchTest {
        t,
        df,
        p: student_t_two_sided_p(t, df),
    })
}

/// The paired t-test: a one-sample t-test of the within-pair differences against 0 (t = mean / SE,
/// df = n − 1), returned in a [`WelchTest`]'s fields; `None` for fewer than two pairs or no spread.
pub fn paired_t(differences: &[f64]) -> Option<WelchTest> {
    let d = describe(differences);
    if d.n < 2 || d.se <= 0.0 || !d.se.is_finite() {
        return None;
    }
    let t = d.mean / d.se;
    let df = (d.n - 1) as f64;
    Some(WelchTest {
        t,
        df,
        p: student_t_two_sided_p(t, df),
    })
}

/// A mean ± SE as a table prints it, or `x (n = 1: no spread)` for a single value (`–` for none).
pub fn mean_se_text(d: &Describe, decimals: usize) -> String {
    match d.n {
        0 => "–".into(),
        1 => format!("{:.*} (n = 1: no spread)", decimals, d.mean),
        _ => format!("{:.*} ± {:.*}", decimals, d.mean, decimals, d.se),
    }
}

/// Two-sided p-value of a Student t statistic `t` with `df` degrees of freedom.
pub fn student_t_two_sided_p(t: f64, df: f64) -> f64 {
    if t.is_nan() || df.is_nan() || df <= 0.0 {
        return f64::NAN;
    }
    if t.is_infinite() {
        return 0.0;
    }
    incomplete_beta(df / (df + t * t), df / 2.0, 0.5).clamp(0.0, 1.0)
}

/// The Student t CDF, P(T ≤ t).
pub fn student_t_cdf(t: f64, df: f64) -> f64 {
    let tail = student_t_two_sided_p(t, df) / 2.0;
    if t >= 0.0 { 1.0 - tail } else { tail }
}

/// ln Γ(x) for x > 0 (Lanczos, g = 7).
pub fn ln_gamma(x: f64) -> f64 {
    const G: f64 = 7.0;
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection: Γ(x)Γ(1−x) = π / sin(πx).
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).abs().ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + G + 0.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// The regularized incomplete beta function I_x(a, b) for 0 ≤ x ≤ 1, a, b > 0.
pub fn incomplete_beta(x: f64, a: f64, b: f64) -> f64 {
    if x.is_nan() || a <= 0.0 || b <= 0.0 {
        return f64::NAN;
    }
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let ln_front = ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln();
    let front = ln_front.exp();
    // The continued fraction converges fast for x < (a+1)/(a+b+2); otherwise use the symmetry.
    if x < (a + 1.0) / (a + b + 2.0) {
        front * beta_continued_fraction(x, a, b) / a
    } else {
        1.0 - front * beta_continued_fraction(1.0 - x, b, a) / b
    }
}

fn beta_continued_fraction(x: f64, a: f64, b: f64) -> f64 {
    const TINY: f64 = 1e-300;
    const EPS: f64 = 1e-15;
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = 1.0 - qab * x / qap;
    if d.abs() < TINY {
        d = TINY;
    }
    d = 1.0 / d;
    let mut h = d;
    for m in 1..=300 {
        let m = f64::from(m);
        let m2 = 2.0 * m;
        let aa = m * (b - m) * x / ((qam + m2) * (a + m2));
        d = 1.0 + aa * d;
        if d.abs() < TINY {
            d = TINY;
        }
        c = 1.0 + aa / c;
        if c.abs() < TINY {
            c = TINY;
        }
        d = 1.0 / d;
        h *= d * c;
        let aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
        d = 1.0 + aa * d;
        if d.abs() < TINY {
            d = TINY;
        }
        c = 1.0 + aa / c;
        if c.abs() < TINY {
            c = TINY;
        }
        d = 1.0 / d;
        let del = d * c;
        h *= del;
        if (del - 1.0).abs() < EPS {
            break;
        }
    }
    h
}

/// Relative change of `b` with respect to `a`, (b − a) / |a|; `None` when `a` is zero or not finite.
pub fn relative_change(a: f64, b: f64) -> Option<f64> {
    (a != 0.0 && a.is_finite() && b.is_finite()).then(|| (b - a) / a.abs())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn ln_gamma_matches_factorials_and_half_integers() {
        assert!(close(ln_gamma(1.0), 0.0, 1e-13));
        assert!(close(ln_gamma(5.0), 24f64.ln(), 1e-12));
        assert!(close(ln_gamma(10.0), 362_880f64.ln(), 1e-11));
        assert!(close(
            ln_gamma(0.5),
            std::f64::consts::PI.sqrt().ln(),
            1e-13
        ));
        assert!(close(ln_gamma(0.25), 1.288_022_524_698_077_5, 1e-12));
    }

    #[test]
    fn incomplete_beta_known_values() {
        // I_x(1, 1) = x; I_x(a, 1) = x^a; I_x(1, b) = 1 − (1−x)^b.
        assert!(close(incomplete_beta(0.3, 1.0, 1.0), 0.3, 1e-13));
        assert!(close(incomplete_beta(0.6, 3.0, 1.0), 0.216, 1e-13));
        assert!(close(
            incomplete_beta(0.2, 1.0, 4.0),
            1.0 - 0.8f64.powi(4),
            1e-13
        ));
        // Symmetry I_x(a,b) = 1 − I_{1−x}(b,a).
        let v = incomplete_beta(0.37, 2.5, 4.2);
        assert!(close(v, 1.0 - incomplete_beta(0.63, 4.2, 2.5), 1e-13));
        // I_0.5(a, a) = 0.5.
        assert!(close(incomplete_beta(0.5, 7.3, 7.3), 0.5, 1e-12));
        assert_eq!(incomplete_beta(0.0, 2.0, 3.0), 0.0);
        assert_eq!(incomplete_beta(1.0, 2.0, 3.0), 1.0);
        assert!(incomplete_beta(0.5, -1.0, 1.0).is_nan());
    }

    #[test]
    fn student_t_matches_tables() {
        // Critical values from standard t tables: P(|T| > t) at the given df.
        for (t, df, p) in [
            (12.706, 1.0, 0.05),
            (2.228, 10.0, 0.05),
            (2.101, 18.0, 0.05),
            (2.878, 18.0, 0.01),
            (1.96, 1e7, 0.05),
        ] {
            let got = student_t_two_sided_p(t, df);
            assert!(close(got, p, 2e-4), "t={t} df={df}: {got} vs {p}");
        }
        // df = 1 is the Cauchy distribution: P(T ≤ t) = 1/2 + atan(t)/π.
        let t: f64 = 0.7;
        let cauchy = 0.5 + t.atan() / std::f64::consts::PI;
        assert!(close(student_t_cdf(t, 1.0), cauchy, 1e-12));
        assert!(close(student_t_cdf(-t, 1.0), 1.0 - cauchy, 1e-12));
        // df = 2: P(T ≤ t) = 1/2 + t / (2√(2 + t²)).
        let exact = 0.5 + 1.3 / (2.0 * (2.0 + 1.3f64 * 1.3).sqrt());
        assert!(close(student_t_cdf(1.3, 2.0), exact, 1e-12));
        assert_eq!(student_t_two_sided_p(0.0, 5.0), 1.0);
        assert_eq!(student_t_two_sided_p(f64::INFINITY, 5.0), 0.0);
    }

    #[test]
    fn welch_matches_a_hand_computation() {
        let a = [19.8, 20.4, 19.6, 17.8, 18.5, 18.9, 18.3, 18.9, 19.5, 22.0];
        let b = [28.2, 26.6, 20.1, 23.3, 25.2, 22.1, 17.7, 27.6, 20.6, 13.7];
        let w = welch(&a, &b).unwrap();
        // Computed independently (Python statistics module; p by Simpson integration of the t density):
        // means 19.37 and 22.51, variances 1.449 and 21.4721.
        assert!(close(w.t, 2.074_014_626_678_365, 1e-9), "{w:?}");
        assert!(close(w.df, 10.209_185_368_660_295, 1e-9), "{w:?}");
        assert!(close(w.p, 0.064_279_997_7, 1e-7), "{w:?}");
        // Swapping the samples flips the sign only.
        let r = welch(&b, &a).unwrap();
        assert!(close(r.t, -w.t, 1e-12) && close(r.p, w.p, 1e-12));
    }

    #[test]
    fn paired_t_matches_a_hand_computation() {
        // Differences 1, 2, 3, 4, 5: mean 3, s² = (4 + 1 + 0 + 1 + 4)/4 = 2.5, SE = √(2.5/5) = √0.5, so
        // t = 3/√0.5 = 4.242 640 687, df = 4. For df = 4 the t CDF is closed-form: with u = t/√(4 + t²),
        // F(t) = 1/2 + 3u/4 − u³/4; u = √(18/22) = 0.904 534, u³ = 0.740 073, F = 0.993 382, p = 2(1 − F) = 0.013 236.
        let t = paired_t(&[1.0, 2.0, 3.0, 4.0, 5.0]).unwrap();
        assert!(close(t.t, 3.0 / 0.5f64.sqrt(), 1e-12), "{t:?}");
        assert_eq!(t.df, 4.0);
        let u = t.t / (4.0 + t.t * t.t).sqrt();
        let closed = 2.0 * (1.0 - (0.5 + 0.75 * u - 0.25 * u * u * u));
        assert!(close(t.p, closed, 1e-12), "{t:?} vs {closed}");
        assert!(close(t.p, 0.013_236, 1e-6), "{t:?}");
        assert!(paired_t(&[2.0]).is_none());
        assert!(paired_t(&[2.0, 2.0]).is_none());
    }

    #[test]
    fn one_value_prints_no_spread() {
        assert_eq!(
            mean_se_text(&describe(&[-47.7]), 1),
            "-47.7 (n = 1: no spread)"
        );
        assert_eq!(mean_se_text(&describe(&[2.0, 4.0]), 2), "3.00 ± 1.00");
        assert_eq!(mean_se_text(&describe(&[]), 2), "–");
    }

    #[test]
    fn degenerate_samples_give_no_test() {
        assert!(welch(&[1.0], &[1.0, 2.0]).is_none());
        assert!(welch(&[1.0, 1.0], &[2.0, 2.0]).is_none());
        let d = describe(&[]);
        assert!(d.mean.is_nan() && d.n == 0);
        let d = describe(&[2.0, 4.0, 6.0]);
        assert!(close(d.mean, 4.0, 1e-15) && close(d.sd, 2.0, 1e-15));
        assert!(close(d.se, 2.0 / 3f64.sqrt(), 1e-15));
        assert_eq!(relative_change(0.0, 1.0), None);
        assert!(close(relative_change(10.0, 5.9).unwrap(), -0.41, 1e-12));
    }

    #[test]
    fn p_values_below_a_thousandth_never_print_as_zero() {
        assert_eq!(format_p(3.2e-12), "< 0.001");
        assert_eq!(format_p(0.000_999), "< 0.001");
        assert_eq!(format_p(0.001), "0.001");
        assert_eq!(format_p(0.0456), "0.046");
        assert_eq!(format_p(f64::NAN), "–");
    }
}
