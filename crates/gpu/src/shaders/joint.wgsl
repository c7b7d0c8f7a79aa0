// The joint reconstruction's Chambolle–Pock iterations (crates/core/src/joint.rs does the same
// on the CPU, step for step and in the same order of summation). The CPU keeps its fields
// pixel-major; here they are plane-major: value k of pixel p is at k·npx + p. One invocation
// per pixel; the per-pixel state lives in arrays of the rig's J and padded band count, which
// specmux-gpu writes over the constants below.

struct Params {
    w: u32,
    h: u32,
    npx: u32,
    // Bands of the cube `clip` reads.
    bands: u32,
    // λ per unit of mean|y| (tv_weight · mean‖a‖), the τ/σ balance, √(τσ‖K‖²)/‖K‖, and γ − 1
    // of the over-relaxation (0: the plain step).
    lambda_per_y: f32,
    ratio: f32,
    step: f32,
    over: f32,
    // Reweighted TV: ε per mean ‖∇α‖ (`reweight_eps`).
    eps: f32,
    // The flush threshold of r per λ at a run's first iteration (`dual_flush`).
    flush: f32,
    _pad1: u32,
    _pad2: u32,
}

// Basis vectors and bands padded to lanes (specmux-gpu writes the rig's values here).
const J: u32 = 8u;
const NBP: u32 = 64u;
const LANES: u32 = 8u;

// `rig`, per rig: a (J planes) | βB by columns (J × NBP) | column minima (J) | maxima (J) |
// η'Q (J × J, row-major) | its eigenvectors (J × J, column i the i-th) | eigenvalues (J).
// `sc`, per frame: [count, mean|y|] (a list the sum appends to), –, λ, τ, σ, the flush
// threshold of r, –,
// then M = (I + τη'Q)⁻¹ (J × J, column-major as on the CPU).
// `tab`, per frame: m = M a (J planes) | t = τωy | c = τω/(1 + τω aᵀm) | k = aᵀm | ω | the TV
// weight w (1 unless reweighted) | the saturation flag (1 where the pixel reads the camera's
// saturation: its data term is one-sided, the CPU's cap = y).
// `st`: α | ᾱ | qx | qy (J planes each). `r`: the constraint dual (NBP planes), then the
// active flag (1 where r ≠ 0 somewhere in the pixel's bands).
@group(0) @binding(0) var<uniform> prm: Params;
@group(0) @binding(1) var<storage, read> rig: array<f32>;
@group(0) @binding(2) var<storage, read> y: array<f32>;
@group(0) @binding(3) var<storage, read_write> sc: array<f32>;
@group(0) @binding(4) var<storage, read_write> tab: array<f32>;
@group(0) @binding(5) var<storage, read_write> st: array<f32>;
@group(0) @binding(6) var<storage, read_write> r: array<f32>;
@group(0) @binding(7) var<storage, read_write> cost: array<f32>;
@group(0) @binding(8) var<storage, read_write> cube: array<f32>;
@group(0) @binding(9) var<storage, read_write> extremes: array<atomic<u32>, 2>;
// The reweighting's list of mean ‖∇α‖ (a count, then the values the sums append).
@group(0) @binding(10) var<storage, read> rw: array<f32>;
// The means of |α| the steps are balanced by (a count, then the seed's, the rebalance's and
// those of each λ set by the host).
@group(0) @binding(11) var<storage, read> bal: array<f32>;
// λ set by the host (a trial of the discrepancy search, or its choice); 0: the rule's
// λ = tv_weight·mean‖a‖·mean|y|.
@group(0) @binding(12) var<storage, read> lam: array<f32>;

const SC_LAMBDA: u32 = 3u;
const SC_TAU: u32 = 4u;
const SC_SIGMA: u32 = 5u;
const SC_FLUSH: u32 = 6u;
// The flush threshold's decay per iteration (the CPU's `FLUSH_DECAY`).
const FLUSH_DECAY: f32 = 0.98;
const SC_MAT: u32 = 8u;
const ALPHA: u32 = 0u;
const BAR: u32 = J;
const QX: u32 = 2u * J;
const QY: u32 = 3u * J;
// The TV weight's and the saturation flag's planes in `tab`.
const TVW: u32 = J + 4u;
const SAT: u32 = J + 5u;

fn at(plane: u32, p: u32) -> u32 {
    return plane * prm.npx + p;
}

// Offsets of the per-rig tables in `rig`.
fn bcol(j: u32, k: u32) -> f32 {
    return rig[J * prm.npx + j * NBP + k];
}
fn col_lo(j: u32) -> f32 {
    return rig[J * prm.npx + J * NBP + j];
}
fn col_hi(j: u32) -> f32 {
    return rig[J * prm.npx + J * NBP + J + j];
}
fn eq(row: u32, col: u32) -> f32 {
    return rig[J * prm.npx + J * NBP + 2u * J + row * J + col];
}
fn eigvec(row: u32, i: u32) -> f32 {
    return rig[J * prm.npx + J * NBP + 2u * J + J * J + row * J + i];
}
fn eigval(i: u32) -> f32 {
    return rig[J * prm.npx + J * NBP + 2u * J + 2u * J * J + i];
}

// Invocation i of a 1-D dispatch folded into (x, y) workgroups of 256.
fn linear(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 256u;
}

// ---- setup (one invocation): λ = tv_weight·mean|y|·mean‖a‖; s = mean|α₀|/λ (1 when either
// is 0); τ = ratio·s·step, σ = step/(ratio·s); M = V diag(1/(1 + τe)) Vᵀ from η'Q = V diag(e) Vᵀ.
@compute @workgroup_size(1)
fn setup() {
    let lambda = target_lambda();
    let mean_alpha = bal[bitcast<u32>(bal[0])];
    var scale = 1.0;
    if lambda > 0.0 && mean_alpha > 0.0 {
        scale = mean_alpha / lambda;
    }
    let tau = prm.ratio * scale * prm.step;
    sc[SC_LAMBDA] = lambda;
    sc[SC_TAU] = tau;
    sc[SC_SIGMA] = prm.step / (prm.ratio * scale);
    for (var c = 0u; c < J; c++) {
        for (var row = 0u; row < J; row++) {
            var v = 0.0;
            for (var i = 0u; i < J; i++) {
                v += eigvec(row, i) * eigvec(c, i) / (1.0 + tau * eigval(i));
            }
            sc[SC_MAT + c * J + row] = v;
        }
    }
}

// The λ a run or a trial takes: the host's, else the rule's from mean|y|.
fn target_lambda() -> f32 {
    if lam[0] > 0.0 {
        return lam[0];
    }
    return prm.lambda_per_y * sc[1];
}

// ---- relambda (per pixel, before `setup` sets the new λ): the TV dual rescaled into the new
// ball, q ← q·λ_new/λ_old (0 when λ_old = 0), and the extrapolation restarted, ᾱ = α (the
// CPU's `set_lambda`; the steps and tables follow from `setup` and `retable`).
@compute @workgroup_size(256)
fn relambda(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = linear(gid, nwg);
    if p >= prm.npx {
        return;
    }
    let old = sc[SC_LAMBDA];
    let f = select(0.0, target_lambda() / old, old > 0.0);
    for (var j = 0u; j < J; j++) {
        st[at(QX + j, p)] *= f;
        st[at(QY + j, p)] *= f;
        st[at(BAR + j, p)] = st[at(ALPHA + j, p)];
    }
}

// out = M v (M column-major, as the CPU's `mat_vec`).
fn mat_vec(v: array<f32, J>) -> array<f32, J> {
    var out: array<f32, J>;
    for (var row = 0u; row < J; row++) {
        var acc = 0.0;
        for (var c = 0u; c < J; c++) {
            acc += sc[SC_MAT + c * J + row] * v[c];
        }
        out[row] = acc;
    }
    return out;
}

// m = M a_p, k = a_pᵀm, t = τωy, c = τω/(1 + τωk) at pixel p (the CPU's `prox_tables`).
fn prox_tables(p: u32) {
    var ap: array<f32, J>;
    for (var j = 0u; j < J; j++) {
        ap[j] = rig[at(j, p)];
    }
    let m = mat_vec(ap);
    var k = 0.0;
    for (var j = 0u; j < J; j++) {
        k += ap[j] * m[j];
        tab[at(j, p)] = m[j];
    }
    let tw = sc[SC_TAU] * tab[at(J + 3u, p)];
    tab[at(J, p)] = tw * y[p];
    tab[at(J + 1u, p)] = tw / (1.0 + tw * k);
    tab[at(J + 2u, p)] = k;
}

// ---- tables (per pixel): the proximal tables and the state's start: ᾱ = α (the seed),
// q = 0, r = 0, not active, the TV weight 1.
@compute @workgroup_size(256)
fn tables(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = linear(gid, nwg);
    if p >= prm.npx {
        return;
    }
    prox_tables(p);
    for (var j = 0u; j < J; j++) {
        st[at(BAR + j, p)] = st[at(ALPHA + j, p)];
        st[at(QX + j, p)] = 0.0;
        st[at(QY + j, p)] = 0.0;
    }
    tab[at(TVW, p)] = 1.0;
    for (var b = 0u; b <= NBP; b++) {
        r[at(b, p)] = 0.0;
    }
}

// ---- retable (per pixel): the proximal tables for a rebalanced τ, the state kept.
@compute @workgroup_size(256)
fn retable(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = linear(gid, nwg);
    if p >= prm.npx {
        return;
    }
    prox_tables(p);
}

// Forward differences of plane `plane` at pixel p = (x, row), 0 across the last column and row.
fn gradient(plane: u32, p: u32, x: u32, row: u32) -> vec2<f32> {
    let v = st[at(plane, p)];
    var d = vec2<f32>(0.0, 0.0);
    if x + 1u < prm.w {
        d.x = st[at(plane, p + 1u)] - v;
    }
    if row + 1u < prm.h {
        d.y = st[at(plane, p + prm.w)] - v;
    }
    return d;
}

// Whether `fit` reaches the reading of a saturated pixel p: its one-sided data term is zero
// there (the CPU's `fit >= cap`).
fn capped(p: u32, fit: f32) -> bool {
    return tab[at(SAT, p)] > 0.5 && fit >= y[p];
}

// y − fit, or 0 where the pixel is saturated and the fit reaches its reading (the CPU's
// `data_residual`).
fn data_residual(p: u32, fit: f32) -> f32 {
    return select(y[p] - fit, 0.0, capped(p, fit));
}

// ½ω(y − aᵀα)² + ½αᵀη'Qα + λ‖∇α‖ at pixel p (the CPU's `pixel_cost`, in f32).
fn pixel_cost(p: u32, x: u32, row: u32) -> f32 {
    var alpha: array<f32, J>;
    var fit = 0.0;
    for (var j = 0u; j < J; j++) {
        alpha[j] = st[at(ALPHA + j, p)];
        fit += rig[at(j, p)] * alpha[j];
    }
    var quad = 0.0;
    for (var i = 0u; i < J; i++) {
        for (var c = 0u; c < J; c++) {
            quad += alpha[i] * eq(i, c) * alpha[c];
        }
    }
    let e = data_residual(p, fit);
    let tv = sc[SC_LAMBDA] * tab[at(TVW, p)] * sqrt(alpha_grad_sq(p, x, row));
    return 0.5 * tab[at(J + 3u, p)] * e * e + 0.5 * quad + tv;
}

// Σ_j a_j² then Σ_j b_j² in one running sum, as the CPU's chained iterators.
fn sum_sq(a: array<f32, J>, b: array<f32, J>) -> f32 {
    var s = 0.0;
    for (var j = 0u; j < J; j++) {
        s += a[j] * a[j];
    }
    for (var j = 0u; j < J; j++) {
        s += b[j] * b[j];
    }
    return s;
}

// The factor that brings a vector of squared norm n2 into the ball of radius r: 1 inside it,
// r/√n2 outside (0 for r = 0); the CPU's `ball_factor`.
fn ball_factor(n2: f32, r: f32) -> f32 {
    if !(n2 > r * r) {
        return 1.0;
    }
    if r > 0.0 {
        return r / sqrt(n2);
    }
    return 0.0;
}

// ‖∇α(p)‖² over the J coefficients and both directions.
fn alpha_grad_sq(p: u32, x: u32, row: u32) -> f32 {
    var gx: array<f32, J>;
    var gy: array<f32, J>;
    for (var j = 0u; j < J; j++) {
        let g = gradient(ALPHA + j, p, x, row);
        gx[j] = g.x;
        gy[j] = g.y;
    }
    return sum_sq(gx, gy);
}

// ---- cost (per pixel): the objective's share of each pixel at the current α.
@compute @workgroup_size(256)
fn objective(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = linear(gid, nwg);
    if p >= prm.npx {
        return;
    }
    cost[p] = pixel_cost(p, p % prm.w, p / prm.w);
}

// ---- residual (per pixel): ω(y − aᵀα)² (one-sided where saturated) into `cost`, for the
// residual ratio Σωr²/#{ω > 0} (the CPU's `weighted_residual`).
@compute @workgroup_size(256)
fn residual(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = linear(gid, nwg);
    if p >= prm.npx {
        return;
    }
    var fit = 0.0;
    for (var j = 0u; j < J; j++) {
        fit += rig[at(j, p)] * st[at(ALPHA + j, p)];
    }
    let e = data_residual(p, fit);
    cost[p] = tab[at(J + 3u, p)] * e * e;
}

// True when min_k (βBᾱ)_k ≥ 0 follows from the per-column extremes of βB alone.
fn surely_feasible(bar: array<f32, J>) -> bool {
    var lower = 0.0;
    for (var j = 0u; j < J; j++) {
        if bar[j] >= 0.0 {
            lower += bar[j] * col_lo(j);
        } else {
            lower += bar[j] * col_hi(j);
        }
    }
    return lower >= 0.0;
}

// ---- dual (per pixel): the pixel's cost at α (for the objective), then
// q ← P_{‖·‖≤λ}(q + σ∇ᾱ) jointly over J and both directions, and
// r ← min(r + σβBᾱ, 0), skipped where r = 0 and the bound proves βBᾱ ≥ 0; both relaxed by γ.
@compute @workgroup_size(256)
fn dual(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = linear(gid, nwg);
    if p >= prm.npx {
        return;
    }
    let x = p % prm.w;
    let row = p / prm.w;
    cost[p] = pixel_cost(p, x, row);
    let lambda = sc[SC_LAMBDA] * tab[at(TVW, p)];
    let sigma = sc[SC_SIGMA];
    var qx: array<f32, J>;
    var qy: array<f32, J>;
    var qx0: array<f32, J>;
    var qy0: array<f32, J>;
    var bar: array<f32, J>;
    for (var j = 0u; j < J; j++) {
        let g = gradient(BAR + j, p, x, row);
        qx0[j] = st[at(QX + j, p)];
        qy0[j] = st[at(QY + j, p)];
        qx[j] = qx0[j] + sigma * g.x;
        qy[j] = qy0[j] + sigma * g.y;
        bar[j] = st[at(BAR + j, p)];
    }
    let f = ball_factor(sum_sq(qx, qy), lambda);
    // Relaxed: q ← t + (γ − 1)(t − q) with t the projected step (the CPU's `relax`).
    for (var j = 0u; j < J; j++) {
        let tx = qx[j] * f;
        let ty = qy[j] * f;
        st[at(QX + j, p)] = tx + prm.over * (tx - qx0[j]);
        st[at(QY + j, p)] = ty + prm.over * (ty - qy0[j]);
    }
    if r[at(NBP, p)] == 0.0 && surely_feasible(bar) {
        return;
    }
    var flag = 0.0;
    for (var k = 0u; k < NBP; k++) {
        var u = 0.0;
        for (var j = 0u; j < J; j++) {
            u += bcol(j, k) * bar[j];
        }
        let old = r[at(k, p)];
        let next = min(old + sigma * u, 0.0);
        let relaxed = next + prm.over * (next - old);
        // Values under the flush threshold set to 0 (the CPU's `dual_flush`).
        let v = select(relaxed, 0.0, abs(relaxed) < sc[SC_FLUSH]);
        r[at(k, p)] = v;
        if v != 0.0 {
            flag = 1.0;
        }
    }
    r[at(NBP, p)] = flag;
}

// ---- flush_start (one invocation, before a run's or a trial's iterations): the threshold
// dual_flush·λ; flush_decay (one invocation, after each iteration): × FLUSH_DECAY.
@compute @workgroup_size(1)
fn flush_start() {
    sc[SC_FLUSH] = prm.flush * sc[SC_LAMBDA];
}

@compute @workgroup_size(1)
fn flush_decay() {
    sc[SC_FLUSH] = sc[SC_FLUSH] * FLUSH_DECAY;
}

// ---- grad_norm (per pixel): g_p = ‖∇α(p)‖ into `cost`, the reweighting's input (its mean
// is appended to `rw` after this).
@compute @workgroup_size(256)
fn grad_norm(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = linear(gid, nwg);
    if p >= prm.npx {
        return;
    }
    cost[p] = sqrt(alpha_grad_sq(p, p % prm.w, p / prm.w));
}

// ---- reweight (per pixel, after grad_norm and its mean): the excess e of g over its 3 × 3
// mean (clipped at the borders), w = ε/(e + ε) with ε = eps · mean g (1 when ε = 0), q projected
// into the ball λw, ᾱ = α (the CPU's `reweight`).
@compute @workgroup_size(256)
fn reweight(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = linear(gid, nwg);
    if p >= prm.npx {
        return;
    }
    let x = p % prm.w;
    let row = p / prm.w;
    let y0 = select(row - 1u, 0u, row == 0u);
    let y1 = min(row + 2u, prm.h);
    let x0 = select(x - 1u, 0u, x == 0u);
    let x1 = min(x + 2u, prm.w);
    // Row sums, then their sum, as the CPU's iterators.
    var sum = 0.0;
    for (var yy = y0; yy < y1; yy++) {
        var rs = 0.0;
        for (var xx = x0; xx < x1; xx++) {
            rs += cost[yy * prm.w + xx];
        }
        sum += rs;
    }
    let mean = sum / f32((y1 - y0) * (x1 - x0));
    let e = max(cost[p] - mean, 0.0);
    let eps = prm.eps * rw[bitcast<u32>(rw[0])];
    var w = 1.0;
    if eps > 0.0 {
        w = eps / (e + eps);
    }
    tab[at(TVW, p)] = w;
    var qx: array<f32, J>;
    var qy: array<f32, J>;
    for (var j = 0u; j < J; j++) {
        qx[j] = st[at(QX + j, p)];
        qy[j] = st[at(QY + j, p)];
    }
    let f = ball_factor(sum_sq(qx, qy), sc[SC_LAMBDA] * w);
    for (var j = 0u; j < J; j++) {
        st[at(QX + j, p)] = qx[j] * f;
        st[at(QY + j, p)] = qy[j] * f;
        st[at(BAR + j, p)] = st[at(ALPHA + j, p)];
    }
}

// (βBᵀr)_j at pixel p in LANES partial sums, added up in lane order (the CPU's
// `basis_t_times`).
fn basis_t_times(j: u32, p: u32) -> f32 {
    var acc: array<f32, LANES>;
    for (var c = 0u; c < NBP; c += LANES) {
        for (var l = 0u; l < LANES; l++) {
            acc[l] += bcol(j, c + l) * r[at(c + l, p)];
        }
    }
    var s = 0.0;
    for (var l = 0u; l < LANES; l++) {
        s += acc[l];
    }
    return s;
}

// ---- primal (per pixel): α⁺ = prox_{τf}(α − τ(∇ᵀq + βBᵀr)) in closed form
// (Sherman–Morrison on (I + τη'Q + τω aaᵀ)⁻¹) from the relaxed point x, then ᾱ = 2α⁺ − x.
@compute @workgroup_size(256)
fn primal(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = linear(gid, nwg);
    if p >= prm.npx {
        return;
    }
    let x = p % prm.w;
    let row = p / prm.w;
    let tau = sc[SC_TAU];
    let constrained = r[at(NBP, p)] != 0.0;
    var start: array<f32, J>;
    var v: array<f32, J>;
    for (var j = 0u; j < J; j++) {
        var left = 0.0;
        if x > 0u {
            left = st[at(QX + j, p - 1u)];
        }
        var up = 0.0;
        if row > 0u {
            up = st[at(QY + j, p - prm.w)];
        }
        let div = st[at(QX + j, p)] - left + st[at(QY + j, p)] - up;
        // The relaxed point x = α + (γ − 1)(ᾱ − α) the prox step starts from (the CPU's).
        let a = st[at(ALPHA + j, p)];
        start[j] = a + prm.over * (st[at(BAR + j, p)] - a);
        v[j] = start[j] + tau * div;
        if constrained {
            v[j] -= tau * basis_t_times(j, p);
        }
    }
    let mv = mat_vec(v);
    var mtv = 0.0;
    for (var j = 0u; j < J; j++) {
        mtv += tab[at(j, p)] * v[j];
    }
    let t = tab[at(J, p)];
    let coef = select(t - tab[at(J + 1u, p)] * (mtv + t * tab[at(J + 2u, p)]), 0.0, capped(p, mtv));
    for (var j = 0u; j < J; j++) {
        let next = mv[j] + coef * tab[at(j, p)];
        st[at(BAR + j, p)] = 2.0 * next - start[j];
        st[at(ALPHA + j, p)] = next;
    }
}

// ---- clip (per pixel, after the cube diag(g)·Bα is mixed): the largest value and the largest
// −value over the bands into `extremes` (non-negative f32 order as their bits), then the
// negative values set to zero.
@compute @workgroup_size(256)
fn clip(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let p = linear(gid, nwg);
    if p >= prm.npx {
        return;
    }
    var hi = 0.0;
    var neg = 0.0;
    for (var b = 0u; b < prm.bands; b++) {
        let v = cube[at(b, p)];
        if v > hi {
            hi = v;
        }
        if -v > neg {
            neg = -v;
        }
        if v < 0.0 {
            cube[at(b, p)] = 0.0;
        }
    }
    atomicMax(&extremes[0], bitcast<u32>(hi));
    atomicMax(&extremes[1], bitcast<u32>(neg));
}
