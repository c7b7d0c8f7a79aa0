//! The state of the rig at time t: which wheel segment(s) the light passes (with the spot's
//! area split across a spoke) and which DMD pattern is shown. Both repeat every wheel turn.

use crate::timing::config::TimingConfig;
use std::f64::consts::PI;

/// Fraction of a unit-radius disk beyond a line at signed distance −u from its centre, i.e. the
/// fraction on the side the disk is moving into once its centre has passed the line by u (in
/// radii, |u| ≤ 1): the circular-segment area, G(u) = ½ + (u·√(1−u²) + asin u)/π.
pub fn disk_fraction_past(u: f64) -> f64 {
    let u = u.clamp(-1.0, 1.0);
    0.5 + (u * (1.0 - u * u).sqrt() + u.asin()) / PI
}

/// Where the light is at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum WheelState {
    /// Wholly inside segment i.
    Inside(usize),
    /// Crossing spoke j (from segment j−1 into segment j); `offset_s` is the time since the spot
    /// centre passed the spoke (negative before).
    Spoke { j: usize, offset_s: f64 },
}

/// The validated timing, precomputed: spoke passage times, crossing half-width, pattern slots.
#[derive(Clone, Debug)]
pub struct Schedule {
    pub n: usize,
    pub period: f64,
    pub rate_hz: f64,
    /// Start angle θ_i of each segment (degrees), θ_0 = 0.
    pub theta_deg: Vec<f64>,
    pub offset_deg: f64,
    /// Spot radius / wheel radius at the spot, r/R.
    pub rho: f64,
    /// Half the time the spot takes to cross a spoke: asin(r/R)/(2π f).
    pub half_crossing_s: f64,
    /// Time in [0, period) at which the spot centre crosses spoke j (entering segment j).
    pub spoke_s: Vec<f64>,
    /// Pattern k's (start in [0, period), duration).
    pub slots: Vec<(f64, f64)>,
}

impl Schedule {
    /// Build from a configuration that has passed `validate`.
    pub fn new(cfg: &TimingConfig) -> Schedule {
        let n = cfg.segment_count();
        let period = cfg.period_s();
        let mut theta_deg = Vec::with_capacity(n);
        let mut acc = 0.0;
        for &d in &cfg.wheel.segments_deg {
            theta_deg.push(acc);
            acc += d;
        }
        let offset_deg = cfg.wheel.index_offset_deg;
        let rho = cfg.wheel.spot_diameter_mm / 2.0 / cfg.wheel.spot_radius_mm;
        let spoke_s = theta_deg
            .iter()
            .map(|&th| ((th - offset_deg) / 360.0).rem_euclid(1.0) * period)
            .collect();
        Schedule {
            n,
            period,
            rate_hz: cfg.wheel.rate_hz,
            theta_deg,
            offset_deg,
            rho,
            half_crossing_s: rho.asin() / (2.0 * PI) * period,
            spoke_s,
            slots: cfg.pattern_slots(),
        }
    }

    /// `t` relative to `origin`, wrapped into [−period/2, period/2).
    fn wrapped(&self, t: f64, origin: f64) -> f64 {
        (t - origin + self.period / 2.0).rem_euclid(self.period) - self.period / 2.0
    }

    /// Which segment or spoke the light passes at time t.
    pub fn wheel_state(&self, t: f64) -> WheelState {
        for (j, &c) in self.spoke_s.iter().enumerate() {
            let dt = self.wrapped(t, c);
            if dt.abs() < self.half_crossing_s {
                return WheelState::Spoke { j, offset_s: dt };
            }
        }
        let alpha = (360.0 * (t / self.period) + self.offset_deg).rem_euclid(360.0);
        let i = self
            .theta_deg
            .iter()
            .rposition(|&th| th <= alpha)
            .unwrap_or(self.n - 1);
        WheelState::Inside(i)
    }

    /// Fraction of segment j's side of spoke j covered by the spot, `offset_s` after its centre
    /// crossed the spoke: G(R·sin(x)/r) with x = 2π f·offset the angle past the spoke.
    pub fn past_spoke_fraction(&self, offset_s: f64) -> f64 {
        if self.rho == 0.0 {
            return if offset_s >= 0.0 { 1.0 } else { 0.0 };
        }
        let x = 2.0 * PI * offset_s / self.period;
        disk_fraction_past(x.sin() / self.rho)
    }

    /// Fraction of the light passing through each segment at time t (sums to 1).
    pub fn light_fractions(&self, t: f64) -> Vec<f64> {
        let mut a = vec![0.0; self.n];
        match self.wheel_state(t) {
            WheelState::Inside(i) => a[i] = 1.0,
            WheelState::Spoke { j, offset_s } => {
                let g = self.past_spoke_fraction(offset_s);
                a[j] += g;
                a[(j + self.n - 1) % self.n] += 1.0 - g;
            }
        }
        a
    }

    /// The pattern the DMD shows at time t, or None in a dark gap.
    pub fn pattern_at(&self, t: f64) -> Option<usize> {
        self.slots
            .iter()
            .position(|&(start, dur)| (t - start).rem_euclid(self.period) < dur)
    }

    /// ∫_{t_a}^{t_b} G dt over part of spoke j's crossing (offsets from the spoke's passage),
    /// exact to rounding: with u = sin φ the area fraction is G = ½ + (φ + sin φ cos φ)/π and
    /// the angle past the spoke x = asin(ρ sin φ), both analytic in φ, so Gauss–Legendre in φ
    /// converges geometrically.
    pub fn past_spoke_integral(&self, off_a: f64, off_b: f64, gl: &GaussLegendre) -> f64 {
        let to_phi = |off: f64| {
            let x = 2.0 * PI * off / self.period;
            (x.sin() / self.rho).clamp(-1.0, 1.0).asin()
        };
        let (pa, pb) = (to_phi(off_a), to_phi(off_b));
        let rho = self.rho;
        let integral_dx = gl.integrate(pa, pb, |phi| {
            let (s, c) = phi.sin_cos();
            let g = 0.5 + (phi + s * c) / PI;
            g * rho * c / (1.0 - rho * rho * s * s).sqrt()
        });
        integral_dx * self.period / (2.0 * PI)
    }

    /// Every time in (a, b) at which the wheel state or the pattern changes.
    pub fn breakpoints(&self, a: f64, b: f64) -> Vec<f64> {
        let mut cuts = vec![a, b];
        let mut add_periodic = |t0: f64| {
            let first = t0 + ((a - t0) / self.period).floor() * self.period;
            let mut t = first;
            while t < b {
                if t > a {
                    cuts.push(t);
                }
                t += self.period;
            }
        };
        for &c in &self.spoke_s {
            add_periodic(c - self.half_crossing_s);
            add_periodic(c + self.half_crossing_s);
        }
        for &(start, dur) in &self.slots {
            add_periodic(start);
            add_periodic(start + dur);
        }
        cuts.sort_by(f64::total_cmp);
        cuts.dedup();
        cuts
    }

    /// E_ik = ∫_a^b a_i(t)·p_k(t) dt in seconds (light through segment i while pattern k shows).
    pub fn energy(&self, a: f64, b: f64, gl: &GaussLegendre) -> Vec<Vec<f64>> {
        let mut e = vec![vec![0.0; self.n]; self.n];
        let cuts = self.breakpoints(a, b);
        for win in cuts.windows(2) {
            let (u, v) = (win[0], win[1]);
            if v <= u {
                continue;
            }
            let mid = 0.5 * (u + v);
            let Some(k) = self.pattern_at(mid) else {
                continue;
            };
            match self.wheel_state(mid) {
                WheelState::Inside(i) => e[i][k] += v - u,
                WheelState::Spoke { j, offset_s } => {
                    let past =
                        self.past_spoke_integral(offset_s - (mid - u), offset_s + (v - mid), gl);
                    e[j][k] += past;
                    e[(j + self.n - 1) % self.n][k] += (v - u) - past;
                }
            }
        }
        e
    }
}

/// Gauss–Legendre nodes and weights on [−1, 1] (Newton on the Legendre recurrence).
#[derive(Clone, Debug)]
pub struct GaussLegendre {
    nodes: Vec<f64>,
    weights: Vec<f64>,
}

impl GaussLegendre {
    pub fn new(n: usize) -> GaussLegendre {
        let mut nodes = vec![0.0; n];
        let mut weights = vec![0.0; n];
        for i in 0..n.div_ceil(2) {
            let mut x = (PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            let mut dp = 0.0;
            for _ in 0..100 {
                let (mut p0, mut p1) = (1.0, x);
                for m in 2..=n {
                    let p2 = ((2 * m - 1) as f64 * x * p1 - (m - 1) as f64 * p0) / m as f64;
                    p0 = p1;
                    p1 = p2;
                }
                dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
                let dx = p1 / dp;
                x -= dx;
                if dx.abs() < 1e-16 {
                    break;
                }
            }
            let w = 2.0 / ((1.0 - x * x) * dp * dp);
            nodes[i] = -x;
            nodes[n - 1 - i] = x;
            weights[i] = w;
            weights[n - 1 - i] = w;
        }
        GaussLegendre { nodes, weights }
    }

    /// ∫_a^b f.
    pub fn integrate(&self, a: f64, b: f64, f: impl Fn(f64) -> f64) -> f64 {
        let (mid, half) = (0.5 * (a + b), 0.5 * (b - a));
        half * self
            .nodes
            .iter()
            .zip(&self.weights)
            .map(|(&x, &w)| w * f(mid + half * x))
            .sum::<f64>()
    }
}
