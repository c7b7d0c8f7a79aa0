// Fourier demultiplexing around the FFT kernels (crates/core/src/demux.rs does the same on the
// CPU): the real frame becomes a complex plane; each carrier's window is cropped from the
// spectrum, shifted to the origin, weighed and divided by the carrier's gain; after the
// inverse FFT each plane is demodulated by its carrier's sub-bin offset, normalised by 1/(w·h),
// and the planes are mixed by M (the exposure crosstalk's inverse, or the identity).

struct Params {
    w: u32,
    h: u32,
    wx: u32,
    wy: u32,
    planes: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

struct Carrier {
    cx: i32,
    cy: i32,
    inv_gain: vec2<f32>,
}

fn cmul(a: vec2<f32>, b: vec2<f32>) -> vec2<f32> {
    return vec2<f32>(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x);
}

// ---- to_complex: frame (f32) → plane of complex values, imaginary part 0.
@group(0) @binding(0) var<storage, read> tc_frame: array<f32>;
@group(0) @binding(1) var<storage, read_write> tc_out: array<vec2<f32>>;
@group(0) @binding(2) var<uniform> tc_p: Params;

@compute @workgroup_size(256)
fn to_complex(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x + gid.y * 65535u * 256u;
    if i >= tc_p.w * tc_p.h { return; }
    tc_out[i] = vec2<f32>(tc_frame[i], 0.0);
}

// ---- crop: Z_k(u, v) = weight(dx, dy) · Y(cx + dx, cy + dy) / gain_k for the bin (u, v) at
// offset (dx, dy) ≡ (u, v) inside the window [−⌊wx/2⌋, wx − ⌊wx/2⌋) × [−⌊wy/2⌋, wy − ⌊wy/2⌋),
// 0 elsewhere. Invocation (u, v, k); planes row-major (index v·w + u).
@group(0) @binding(0) var<storage, read> cr_spec: array<vec2<f32>>;
@group(0) @binding(1) var<storage, read_write> cr_out: array<vec2<f32>>;
@group(0) @binding(2) var<storage, read> cr_carriers: array<Carrier>;
@group(0) @binding(3) var<storage, read> cr_weights: array<f32>;
@group(0) @binding(4) var<uniform> cr_p: Params;

// The signed offset of index u inside a window of `win` bins on an axis of `n`, or `win` (out
// of the window) when u is in no position of it.
fn offset(u: u32, win: u32, n: u32) -> i32 {
    let half = i32(win / 2u);
    var d = i32(u);
    if d >= i32(win) - half {
        d = d - i32(n);
    }
    if d < -half {
        return i32(win);
    }
    return d;
}

// a mod n for a ≥ −4n (a window's bins lie within one frame of its centre, which lies within
// half a frame of 0). No `%` on a negative i32: on the NVIDIA Vulkan driver (580, through
// naga) it came out as the unsigned remainder of the bit pattern, right only for n = 2^k.
fn wrap(a: i32, n: u32) -> u32 {
    return u32(a + 4 * i32(n)) % n;
}

@compute @workgroup_size(16, 16)
fn crop(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = cr_p;
    if gid.x >= p.w || gid.y >= p.h || gid.z >= p.planes { return; }
    let out_i = gid.z * p.w * p.h + gid.y * p.w + gid.x;
    let dx = offset(gid.x, p.wx, p.w);
    let dy = offset(gid.y, p.wy, p.h);
    if dx == i32(p.wx) || dy == i32(p.wy) {
        cr_out[out_i] = vec2<f32>(0.0, 0.0);
        return;
    }
    let c = cr_carriers[gid.z];
    let kx = wrap(c.cx + dx, p.w);
    let ky = wrap(c.cy + dy, p.h);
    let wt = cr_weights[u32(dy + i32(p.wy / 2u)) * p.wx + u32(dx + i32(p.wx / 2u))];
    cr_out[out_i] = cmul(cr_spec[ky * p.w + kx], c.inv_gain) * wt;
}

// ---- demod: x_i(p) = Σ_k M_ik · Re(z_k(p) · ex_k(x) · ey_k(y)), with
// ex_k(x)·ey_k(y) = e^{−2πi δ_k·p}/(w·h) tabulated per axis in f64 on the host.
@group(0) @binding(0) var<storage, read> dm_z: array<vec2<f32>>;
@group(0) @binding(1) var<storage, read_write> dm_out: array<f32>;
@group(0) @binding(2) var<storage, read> dm_ex: array<vec2<f32>>;
@group(0) @binding(3) var<storage, read> dm_ey: array<vec2<f32>>;
@group(0) @binding(4) var<storage, read> dm_mix: array<f32>;
@group(0) @binding(5) var<uniform> dm_p: Params;

const MAX_PLANES: u32 = 16u;

@compute @workgroup_size(16, 16)
fn demod(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = dm_p;
    if gid.x >= p.w || gid.y >= p.h { return; }
    let npx = p.w * p.h;
    let px = gid.y * p.w + gid.x;
    var z: array<f32, MAX_PLANES>;
    for (var k = 0u; k < p.planes; k++) {
        let e = cmul(dm_ex[k * p.w + gid.x], dm_ey[k * p.h + gid.y]);
        let v = dm_z[k * npx + px];
        z[k] = v.x * e.x - v.y * e.y;
    }
    for (var i = 0u; i < p.planes; i++) {
        var acc = 0.0;
        for (var k = 0u; k < p.planes; k++) {
            acc += dm_mix[i * p.planes + k] * z[k];
        }
        dm_out[i * npx + px] = acc;
    }
}
