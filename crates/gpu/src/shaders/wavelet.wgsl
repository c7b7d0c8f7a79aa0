// One level of the orthogonal 2-D periodic wavelet transform on J planes (crates/core/src/
// wavelet.rs does the same on the CPU), out of place between the data and a scratch buffer:
// the forward rows split [a | d] of the top-left bw × bh block, then its columns; the inverse
// undoes the columns, then the rows. Planes are w wide, npx values apart.

struct Level {
    w: u32,
    bw: u32,
    bh: u32,
    npx: u32,
    taps: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<storage, read> src: array<f32>;
@group(0) @binding(1) var<storage, read_write> dst: array<f32>;
// h[0 .. taps], then g[0 .. taps] from index 4.
@group(0) @binding(2) var<storage, read> filters: array<f32, 8>;
@group(0) @binding(3) var<uniform> lv: Level;

// Invocation (i, row, plane): a_i = Σ_n h[n]·x[(2i+n) mod bw], d_i = Σ_n g[n]·x[…].
@compute @workgroup_size(16, 16)
fn rows_forward(@builtin(global_invocation_id) gid: vec3<u32>) {
    let half = lv.bw / 2u;
    if gid.x >= half || gid.y >= lv.bh {
        return;
    }
    let base = gid.z * lv.npx + gid.y * lv.w;
    var a = 0.0;
    var d = 0.0;
    for (var n = 0u; n < lv.taps; n++) {
        let v = src[base + (2u * gid.x + n) % lv.bw];
        a += filters[n] * v;
        d += filters[4u + n] * v;
    }
    dst[base + gid.x] = a;
    dst[base + half + gid.x] = d;
}

// Invocation (column, i, plane): the same split down a column of the block.
@compute @workgroup_size(16, 16)
fn cols_forward(@builtin(global_invocation_id) gid: vec3<u32>) {
    let half = lv.bh / 2u;
    if gid.x >= lv.bw || gid.y >= half {
        return;
    }
    let base = gid.z * lv.npx + gid.x;
    var a = 0.0;
    var d = 0.0;
    for (var n = 0u; n < lv.taps; n++) {
        let v = src[base + ((2u * gid.y + n) % lv.bh) * lv.w];
        a += filters[n] * v;
        d += filters[4u + n] * v;
    }
    dst[base + gid.y * lv.w] = a;
    dst[base + (half + gid.y) * lv.w] = d;
}

// x[m] = Σ over (i, n) with 2i + n ≡ m (mod len) of h[n]·a_i + g[n]·d_i, where a_i is at
// element i and d_i at element len/2 + i of a line starting at `base`, `stride` apart.
fn synthesis(base: u32, stride: u32, len: u32, m: u32) -> f32 {
    let half = len / 2u;
    var acc = 0.0;
    for (var n = 0u; n < lv.taps; n++) {
        if (m + n) % 2u == 0u {
            let i = ((m + len - n) % len) / 2u;
            acc += filters[n] * src[base + i * stride] + filters[4u + n] * src[base + (half + i) * stride];
        }
    }
    return acc;
}

// Invocation (column, row m, plane).
@compute @workgroup_size(16, 16)
fn cols_inverse(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= lv.bw || gid.y >= lv.bh {
        return;
    }
    let base = gid.z * lv.npx + gid.x;
    dst[base + gid.y * lv.w] = synthesis(base, lv.w, lv.bh, gid.y);
}

// Invocation (column m, row, plane).
@compute @workgroup_size(16, 16)
fn rows_inverse(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= lv.bw || gid.y >= lv.bh {
        return;
    }
    let base = gid.z * lv.npx + gid.y * lv.w;
    dst[base + gid.x] = synthesis(base, 1u, lv.bw, gid.x);
}
