// Per-pixel non-negative unmixing (crates/core/src/unmix.rs and unmix/dual.rs do the same on
// the CPU), in two kernels: `project` gives every pixel r = P x̂ (P = diag(gain)·B·H⁻¹Fᵀ) and
// queues those with a negative band; `solve_queued` solves each queued pixel exactly by
// Goldfarb–Idnani's dual active-set method from the unconstrained minimiser,
// min ½αᵀHα − gᵀα s.t. Bα ≥ 0, with J ≤ 8 variables and ≤ 64 bands, in f32, step for step as
// the CPU's f64 code; the cube is max(Bα, 0)·gain. Two kernels keep the solver's warps full of
// pixels that need it, and the fast path's kernel small.

struct Params {
    npx: u32,
    // Offsets into `tables` of M (J × channels), B (bands × J row-major), 1/‖b_k‖_{H⁻¹} (bands),
    // gains (bands), L⁻ᵀ (8 × 8 column-major); P (bands × channels) is at 0.
    off_unc: u32,
    off_basis: u32,
    off_binv: u32,
    off_gain: u32,
    off_linv: u32,
    // A band counts as violated below −tol·scale; the new band counts as dependent on the
    // active ones when ‖d₂‖² ≤ dependent·‖d‖² (f32 values of the CPU's 1e-12 and 1e-13).
    tol: f32,
    dependent: f32,
}

@group(0) @binding(0) var<storage, read> xhat: array<f32>;
@group(0) @binding(1) var<storage, read_write> cube: array<f32>;
@group(0) @binding(2) var<storage, read> tables: array<f32>;
// [constrained (= queued) pixels, bound pixels, total iterations, max iterations,
//  no convergence, infeasible]
@group(0) @binding(3) var<storage, read_write> stats: array<atomic<u32>, 8>;
@group(0) @binding(4) var<uniform> prm: Params;

// J, bands and channels of the rig: GpuUnmixer::new writes the rig's values over these
// maxima before compiling, so every array has its exact size and every loop a constant trip
// count (the compiler can keep the solver's state in registers rather than local memory).
const MAXB: u32 = 8u;
const MAXM: u32 = 64u;
const MAXC: u32 = 16u;
const MAX_ITERATIONS: u32 = 500u;
// Stands for +∞ (WGSL has no infinity literal); every finite step is far below it.
const BIG: f32 = 3.0e38;

var<private> s: array<f32, MAXM>;
var<private> jm: array<f32, MAXB * MAXB>; // J = L⁻ᵀQ, column-major: jm[col * MAXB + row]
var<private> rm: array<f32, MAXB * MAXB>; // R, upper triangular: rm[i * MAXB + k]
var<private> act: array<u32, MAXB>;
var<private> mu: array<f32, MAXB>;
var<private> alpha: array<f32, MAXB>;
// The working set as a bit mask over the bands (two words of 32): 8 bytes of private memory
// where a bool array took 256, and private arrays here live in the GPU's local memory.
var<private> in_w: vec2<u32>;

fn in_working_set(k: u32) -> bool {
    return (in_w[k / 32u] & (1u << (k % 32u))) != 0u;
}

fn set_working(k: u32, on: bool) {
    let bit = 1u << (k % 32u);
    if on { in_w[k / 32u] |= bit; } else { in_w[k / 32u] &= ~bit; }
}
var<private> q: u32;

fn basis(k: u32, j: u32) -> f32 {
    return tables[prm.off_basis + k * MAXB + j];
}

// s = Bα on the bands.
fn spectrum() {
    for (var k = 0u; k < MAXM; k++) {
        var acc = 0.0;
        for (var j = 0u; j < MAXB; j++) {
            acc += basis(k, j) * alpha[j];
        }
        s[k] = acc;
    }
}

// Columns a and b of J: a ← c·a + sn·b, b ← c·b − sn·a.
fn rotate_columns(a: u32, b: u32, c: f32, sn: f32) {
    for (var i = 0u; i < MAXB; i++) {
        let x = jm[a * MAXB + i];
        let y = jm[b * MAXB + i];
        jm[a * MAXB + i] = c * x + sn * y;
        jm[b * MAXB + i] = c * y - sn * x;
    }
}

// Add band `band` with multiplier `mu_p`, given d = Jᵀb: rotate d's tail into d[q].
fn add_band(d: ptr<function, array<f32, MAXB>>, band: u32, mu_p: f32) {
    for (var i = MAXB - 1u; i > q; i--) {
        let x = (*d)[i - 1u];
        let y = (*d)[i];
        let h = sqrt(x * x + y * y);
        if h > 0.0 {
            (*d)[i - 1u] = h;
            (*d)[i] = 0.0;
            rotate_columns(i - 1u, i, x / h, y / h);
        }
    }
    for (var i = 0u; i <= q; i++) {
        rm[i * MAXB + q] = (*d)[i];
    }
    act[q] = band;
    mu[q] = mu_p;
    q += 1u;
}

// Drop the active band at position l: remove R's column, restore the triangle by Givens
// rotations of R's rows and the matching columns of J.
fn drop_band(l: u32) {
    for (var k = l; k + 1u < q; k++) {
        for (var i = 0u; i <= k + 1u; i++) {
            rm[i * MAXB + k] = rm[i * MAXB + k + 1u];
        }
        act[k] = act[k + 1u];
        mu[k] = mu[k + 1u];
    }
    for (var i = l; i + 1u < q; i++) {
        let x = rm[i * MAXB + i];
        let y = rm[(i + 1u) * MAXB + i];
        let h = sqrt(x * x + y * y);
        if h > 0.0 {
            let c = x / h;
            let sn = y / h;
            for (var k = i; k + 1u < q; k++) {
                let a = rm[i * MAXB + k];
                let b = rm[(i + 1u) * MAXB + k];
                rm[i * MAXB + k] = c * a + sn * b;
                rm[(i + 1u) * MAXB + k] = c * b - sn * a;
            }
            rotate_columns(i, i + 1u, c, sn);
        }
    }
    q -= 1u;
}

// The most violated band (values normalised by ‖b_k‖_{H⁻¹}) outside the working set, or MAXM.
fn most_violated(tol: f32) -> u32 {
    var p = MAXM;
    var worst = -tol;
    for (var k = 0u; k < MAXM; k++) {
        let v = s[k] * tables[prm.off_binv + k];
        if !in_working_set(k) && v < worst {
            worst = v;
            p = k;
        }
    }
    return p;
}

// Goldfarb–Idnani from α = the unconstrained minimiser (s = Bα). Returns the iterations, or
// 0xffffffff when it did not converge, 0xfffffffe when no step is finite (infeasible).
fn active_set(scale: f32) -> u32 {
    let n = MAXB;
    // L⁻ᵀ is stored with the core's stride of 8.
    for (var col = 0u; col < MAXB; col++) {
        for (var row = 0u; row < MAXB; row++) {
            jm[col * MAXB + row] = tables[prm.off_linv + col * 8u + row];
            rm[col * MAXB + row] = 0.0;
        }
    }
    q = 0u;
    in_w = vec2<u32>(0u, 0u);
    var iterations = 0u;
    loop {
        let p = most_violated(prm.tol * scale);
        if p == MAXM { break; }
        var bp: array<f32, MAXB>;
        for (var j = 0u; j < MAXB; j++) { bp[j] = select(0.0, basis(p, j), j < n); }
        var mu_p = 0.0;
        loop {
            iterations += 1u;
            if iterations > MAX_ITERATIONS { return 0xffffffffu; }
            // Declared in the loop, but set here: naga hoists a loop's `var` to the function
            // and does not zero it again on each pass.
            var d: array<f32, MAXB>;
            var z: array<f32, MAXB>;
            var rr: array<f32, MAXB>;
            var dd = 0.0;
            var d2 = 0.0;
            for (var i = 0u; i < MAXB; i++) {
                z[i] = 0.0;
                rr[i] = 0.0;
                var acc = 0.0;
                for (var r = 0u; r < n; r++) { acc += jm[i * MAXB + r] * bp[r]; }
                d[i] = acc;
                dd += acc * acc;
                if i >= q && i < n { d2 += acc * acc; }
            }
            // Primal direction z = J₂d₂, dual direction rr = R⁻¹d₁.
            for (var i = q; i < n; i++) {
                for (var l = 0u; l < MAXB; l++) { z[l] += jm[i * MAXB + l] * d[i]; }
            }
            for (var ii = 0u; ii < q; ii++) {
                let i = q - 1u - ii;
                var acc = 0.0;
                for (var k = i + 1u; k < q; k++) { acc += rm[i * MAXB + k] * rr[k]; }
                rr[i] = (d[i] - acc) / rm[i * MAXB + i];
            }
            // Partial step: the first active multiplier to reach zero.
            var t1 = BIG;
            var dropped = MAXB;
            for (var k = 0u; k < q; k++) {
                if rr[k] > 0.0 {
                    let t = mu[k] / rr[k];
                    if t < t1 { t1 = t; dropped = k; }
                }
            }
            // Full step: band p becomes exactly satisfied.
            var zb = 0.0;
            var sp = 0.0;
            for (var l = 0u; l < n; l++) { zb += z[l] * bp[l]; sp += bp[l] * alpha[l]; }
            var t2 = BIG;
            if d2 > prm.dependent * dd && zb > 0.0 { t2 = -sp / zb; }
            var t = t2;
            if t1 < t2 { t = t1; } else { dropped = MAXB; }
            if !(t < BIG) { return 0xfffffffeu; }
            for (var k = 0u; k < q; k++) { mu[k] -= t * rr[k]; }
            mu_p += t;
            if t2 < BIG {
                for (var l = 0u; l < n; l++) { alpha[l] += t * z[l]; }
            }
            if dropped < MAXB {
                set_working(act[dropped], false);
                drop_band(dropped);
            } else {
                add_band(&d, p, mu_p);
                set_working(p, true);
                if q == n {
                    // n independent homogeneous constraints meet only at α = 0.
                    for (var l = 0u; l < MAXB; l++) { alpha[l] = 0.0; }
                }
                break;
            }
        }
        spectrum();
    }
    return iterations;
}

// Counters of this workgroup, added to `stats` once per workgroup: bound pixels, total
// iterations, max iterations, no convergence, infeasible (stats[1..6]).
var<workgroup> wg_stats: array<atomic<u32>, 5>;

// The exact solution of pixel px: s ← max(Bα, 0)·gain, this workgroup's counters updated.
// False when the active set failed (the pixel is counted, its bands are not written).
fn solve(px: u32) -> bool {
    var x: array<f32, MAXC>;
    for (var i = 0u; i < MAXC; i++) { x[i] = xhat[i * prm.npx + px]; }
    for (var j = 0u; j < MAXB; j++) {
        var acc = 0.0;
        if j < MAXB {
            for (var i = 0u; i < MAXC; i++) { acc += tables[prm.off_unc + j * MAXC + i] * x[i]; }
        }
        alpha[j] = acc;
    }
    spectrum();
    var scale = 0.0;
    for (var k = 0u; k < MAXM; k++) { scale = max(scale, abs(s[k])); }
    let it = active_set(scale);
    if it == 0xffffffffu { atomicAdd(&wg_stats[3], 1u); return false; }
    if it == 0xfffffffeu { atomicAdd(&wg_stats[4], 1u); return false; }
    if q > 0u { atomicAdd(&wg_stats[0], 1u); }
    atomicAdd(&wg_stats[1], it);
    atomicMax(&wg_stats[2], it);
    for (var k = 0u; k < MAXM; k++) {
        s[k] = max(s[k], 0.0) * tables[prm.off_gain + k];
    }
    return true;
}

// Pixels whose fast-path spectrum went negative, in the order they were queued; their count
// is stats[0].
@group(0) @binding(5) var<storage, read_write> queue: array<u32>;

var<workgroup> wg_count: atomic<u32>;
var<workgroup> wg_base: u32;

// The fast path for every pixel: r = P x̂ (in the CPU's order of summation) written to the
// cube; a pixel with a negative band is queued for `solve_queued`. A workgroup reserves its
// queue slots with one global atomic.
@compute @workgroup_size(64)
fn project(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let px = gid.x + gid.y * 65535u * 64u;
    var slot = 0xffffffffu;
    if px < prm.npx {
        var x: array<f32, MAXC>;
        for (var i = 0u; i < MAXC; i++) { x[i] = xhat[i * prm.npx + px]; }
        var minr = BIG;
        for (var k = 0u; k < MAXM; k++) {
            var acc = tables[k * MAXC] * x[0];
            for (var i = 1u; i < MAXC; i++) { acc += tables[k * MAXC + i] * x[i]; }
            cube[k * prm.npx + px] = acc;
            minr = min(minr, acc);
        }
        if minr < 0.0 {
            slot = atomicAdd(&wg_count, 1u);
        }
    }
    workgroupBarrier();
    if lid == 0u {
        wg_base = atomicAdd(&stats[0], atomicLoad(&wg_count));
    }
    workgroupBarrier();
    if slot != 0xffffffffu {
        queue[wg_base + slot] = px;
    }
}

// The exact solve of each queued pixel, its bands overwriting the fast path's.
@compute @workgroup_size(64)
fn solve_queued(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = gid.x + gid.y * 65535u * 64u;
    if i < atomicLoad(&stats[0]) {
        let px = queue[i];
        if solve(px) {
            for (var k = 0u; k < MAXM; k++) { cube[k * prm.npx + px] = s[k]; }
        }
    }
    workgroupBarrier();
    if lid == 0u {
        atomicAdd(&stats[1], atomicLoad(&wg_stats[0]));
        atomicAdd(&stats[2], atomicLoad(&wg_stats[1]));
        atomicMax(&stats[3], atomicLoad(&wg_stats[2]));
        atomicAdd(&stats[4], atomicLoad(&wg_stats[3]));
        atomicAdd(&stats[5], atomicLoad(&wg_stats[4]));
    }
}
