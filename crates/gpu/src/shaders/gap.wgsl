// GAP de-aliasing's per-pixel kernels (crates/core/src/gap.rs does the same on the CPU):
// the projection onto {Y = S X} (accelerated: onto Y_acc), the wavelet groups' scores and
// their shrinkage, and the two-step sums that give the residual and GAP-TV's λ without a
// round trip to the host. Planes are row-major and plane-major: value k of pixel p is at k·npx + p.

struct Params {
    npx: u32,
    planes: u32,
    // 1: accelerated GAP (Liao 2014 §III-C).
    accelerate: u32,
    _pad: u32,
}

// Invocation i of a 1-D dispatch folded into (x, y) workgroups of 256.
fn linear(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 256u;
}

var<workgroup> sums: array<f32, 256>;

// Σ v over the workgroup (a tree in workgroup memory); every invocation must call it.
fn workgroup_sum(lid: u32, v: f32) -> f32 {
    sums[lid] = v;
    workgroupBarrier();
    for (var s = 128u; s > 0u; s >>= 1u) {
        if lid < s {
            sums[lid] += sums[lid + s];
        }
        workgroupBarrier();
    }
    return sums[0];
}

// ---- project: e = y − Σ_k s_k v_k; accelerated: y_acc += e, t = (y_acc − Σ s v)/Σ s²,
// else t = e/Σ s²; v_k += s_k·t. Each workgroup's Σ e² goes to `partials`.
@group(0) @binding(0) var<storage, read_write> pj_v: array<f32>;
@group(0) @binding(1) var<storage, read> pj_s: array<f32>;
@group(0) @binding(2) var<storage, read> pj_y: array<f32>;
@group(0) @binding(3) var<storage, read_write> pj_ya: array<f32>;
@group(0) @binding(4) var<storage, read> pj_inv: array<f32>;
@group(0) @binding(5) var<storage, read_write> pj_partials: array<f32>;
@group(0) @binding(6) var<uniform> pj_p: Params;

@compute @workgroup_size(256)
fn project(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    let n = pj_p.npx;
    let p = linear(gid, nwg);
    var e2 = 0.0;
    if p < n {
        var sv = 0.0;
        for (var k = 0u; k < pj_p.planes; k++) {
            sv += pj_s[k * n + p] * pj_v[k * n + p];
        }
        let e = pj_y[p] - sv;
        e2 = e * e;
        var t = e * pj_inv[p];
        if pj_p.accelerate == 1u {
            let ya = pj_ya[p] + e;
            pj_ya[p] = ya;
            t = (ya - sv) * pj_inv[p];
        }
        for (var k = 0u; k < pj_p.planes; k++) {
            pj_v[k * n + p] += pj_s[k * n + p] * t;
        }
    }
    let total = workgroup_sum(lid, e2);
    if lid == 0u {
        pj_partials[wid.x + wid.y * nwg.x] = total;
    }
}

// ---- abs_sum: each workgroup's Σ |v| over the planes (GAP-TV's λ is a fraction of the
// seed's mean |v|).
@group(0) @binding(0) var<storage, read> ab_v: array<f32>;
@group(0) @binding(1) var<storage, read_write> ab_partials: array<f32>;
@group(0) @binding(2) var<uniform> ab_p: Params;

@compute @workgroup_size(256)
fn abs_sum(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    let i = linear(gid, nwg);
    var v = 0.0;
    if i < ab_p.npx * ab_p.planes {
        v = abs(ab_v[i]);
    }
    let total = workgroup_sum(lid, v);
    if lid == 0u {
        ab_partials[wid.x + wid.y * nwg.x] = total;
    }
}

// ---- finish: scale · Σ partials, appended to a list (one workgroup).
struct Finish {
    partials: u32,
    scale: f32,
    _pad0: u32,
    _pad1: u32,
}

struct List {
    count: u32,
    values: array<f32>,
}

@group(0) @binding(0) var<storage, read> fi_partials: array<f32>;
@group(0) @binding(1) var<storage, read_write> fi_out: List;
@group(0) @binding(2) var<uniform> fi_p: Finish;

@compute @workgroup_size(256)
fn finish(@builtin(local_invocation_index) lid: u32) {
    var v = 0.0;
    for (var i = lid; i < fi_p.partials; i += 256u) {
        v += fi_partials[i];
    }
    let total = workgroup_sum(lid, v);
    if lid == 0u {
        fi_out.values[fi_out.count] = total * fi_p.scale;
        fi_out.count += 1u;
    }
}

// ---- score: ‖W_G‖/β_G of the group at each coefficient position (J values, one per plane);
// the scaling band (β = 0) is never shrunk and gets no score.
@group(0) @binding(0) var<storage, read> sc_c: array<f32>;
@group(0) @binding(1) var<storage, read> sc_beta: array<f32>;
@group(0) @binding(2) var<storage, read_write> sc_score: array<f32>;
@group(0) @binding(3) var<uniform> sc_p: Params;

@compute @workgroup_size(256)
fn score(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let n = sc_p.npx;
    let p = linear(gid, nwg);
    if p >= n {
        return;
    }
    let b = sc_beta[p];
    if b == 0.0 {
        sc_score[p] = 0.0;
        return;
    }
    var a = 0.0;
    for (var k = 0u; k < sc_p.planes; k++) {
        let c = sc_c[k * n + p];
        a += c * c;
    }
    sc_score[p] = sqrt(a) / b;
}

// ---- shrink: W_G ← W_G · (1 − λ/score) where score > λ, else 0; λ's bits are word 0 of
// `sh_lambda` (the selection's result).
@group(0) @binding(0) var<storage, read_write> sh_c: array<f32>;
@group(0) @binding(1) var<storage, read> sh_beta: array<f32>;
@group(0) @binding(2) var<storage, read> sh_score: array<f32>;
@group(0) @binding(3) var<storage, read> sh_lambda: array<u32>;
@group(0) @binding(4) var<uniform> sh_p: Params;

@compute @workgroup_size(256)
fn shrink(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let n = sh_p.npx;
    let p = linear(gid, nwg);
    if p >= n || sh_beta[p] == 0.0 {
        return;
    }
    let lambda = bitcast<f32>(sh_lambda[0]);
    let s = sh_score[p];
    var f = 0.0;
    if s > lambda {
        f = 1.0 - lambda / s;
    }
    for (var k = 0u; k < sh_p.planes; k++) {
        sh_c[k * n + p] *= f;
    }
}

// ---- non_finite: count the NaN and infinite values (by their exponent bits, which no
// fast-math assumption removes).
@group(0) @binding(0) var<storage, read> nf_v: array<f32>;
@group(0) @binding(1) var<storage, read_write> nf_count: array<atomic<u32>>;
@group(0) @binding(2) var<uniform> nf_p: Params;

@compute @workgroup_size(256)
fn non_finite(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear(gid, nwg);
    if i < nf_p.npx * nf_p.planes && (bitcast<u32>(nf_v[i]) & 0x7f800000u) == 0x7f800000u {
        atomicAdd(&nf_count[0], 1u);
    }
}
