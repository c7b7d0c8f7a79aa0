// One Stockham autosort pass of a batched 1-D complex FFT (Govindaraju et al., SC 2008):
// invocation j of N/R loads R values spaced N/R apart, twiddles them by
// exp(dir·2πi·r·(j mod Ns)/(Ns·R)), does a radix-R DFT and stores them Ns apart at
// (j / Ns)·Ns·R + j mod Ns. After passes whose radices multiply to N the line is transformed,
// in natural order. Twiddles come from a table exp(−2πi t/N), t < N, computed in f64 on the
// host: a GPU's sin/cos may be off by 2^-11 (Vulkan's bound), the table is exact to f32.
// A line is `lines` lines of `n` values per plane; the address of value i of line l of plane z
// is z·plane_stride + l·line_stride + i·elem_stride.

struct Pass {
    n: u32,
    ns: u32,
    elem_stride: u32,
    line_stride: u32,
    lines: u32,
    plane_stride: u32,
    // 1: invocation x runs over lines (column passes: neighbours read neighbouring addresses).
    lines_fastest: u32,
    tw_offset: u32,
    // −1 forward, +1 inverse.
    dir: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<storage, read> src: array<vec2<f32>>;
@group(0) @binding(1) var<storage, read_write> dst: array<vec2<f32>>;
@group(0) @binding(2) var<storage, read> twiddles: array<vec2<f32>>;
@group(0) @binding(3) var<uniform> pass_: Pass;

const SIN60: f32 = 0.86602540378443864676;
const C1: f32 = 0.30901699437494742410; // cos 2π/5
const C2: f32 = -0.80901699437494742410; // cos 4π/5
const S1: f32 = 0.95105651629515357212; // sin 2π/5
const S2: f32 = 0.58778525229247312917; // sin 4π/5

fn cmul(a: vec2<f32>, b: vec2<f32>) -> vec2<f32> {
    return vec2<f32>(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x);
}

// i·dir·a
fn rot(a: vec2<f32>) -> vec2<f32> {
    return pass_.dir * vec2<f32>(-a.y, a.x);
}

// The (j, line, plane) of this invocation, or line = lines when it is out of range.
fn coords(gid: vec3<u32>, r: u32) -> vec3<u32> {
    var j = gid.x;
    var line = gid.y;
    if pass_.lines_fastest == 1u {
        j = gid.y;
        line = gid.x;
    }
    if j >= pass_.n / r || line >= pass_.lines {
        return vec3<u32>(0u, pass_.lines, 0u);
    }
    return vec3<u32>(j, line, gid.z);
}

fn base(c: vec3<u32>) -> u32 {
    return c.z * pass_.plane_stride + c.y * pass_.line_stride;
}

// Value r of invocation j, twiddled.
fn load(b: u32, j: u32, r: u32, radix: u32) -> vec2<f32> {
    let v = src[b + (j + r * (pass_.n / radix)) * pass_.elem_stride];
    if r == 0u {
        return v;
    }
    let k = j % pass_.ns;
    let t = (r * k * (pass_.n / (pass_.ns * radix))) % pass_.n;
    var w = twiddles[pass_.tw_offset + t];
    w.y = -pass_.dir * w.y;
    return cmul(v, w);
}

fn store(b: u32, j: u32, r: u32, radix: u32, v: vec2<f32>) {
    let k = j % pass_.ns;
    let out = (j / pass_.ns) * pass_.ns * radix + k + r * pass_.ns;
    dst[b + out * pass_.elem_stride] = v;
}

@compute @workgroup_size(64)
fn radix2(@builtin(global_invocation_id) gid: vec3<u32>) {
    let c = coords(gid, 2u);
    if c.y >= pass_.lines { return; }
    let b = base(c);
    let v0 = load(b, c.x, 0u, 2u);
    let v1 = load(b, c.x, 1u, 2u);
    store(b, c.x, 0u, 2u, v0 + v1);
    store(b, c.x, 1u, 2u, v0 - v1);
}

@compute @workgroup_size(64)
fn radix3(@builtin(global_invocation_id) gid: vec3<u32>) {
    let c = coords(gid, 3u);
    if c.y >= pass_.lines { return; }
    let b = base(c);
    let v0 = load(b, c.x, 0u, 3u);
    let v1 = load(b, c.x, 1u, 3u);
    let v2 = load(b, c.x, 2u, 3u);
    let t = v1 + v2;
    let m = v0 - 0.5 * t;
    let d = rot(SIN60 * (v1 - v2));
    store(b, c.x, 0u, 3u, v0 + t);
    store(b, c.x, 1u, 3u, m + d);
    store(b, c.x, 2u, 3u, m - d);
}

@compute @workgroup_size(64)
fn radix4(@builtin(global_invocation_id) gid: vec3<u32>) {
    let c = coords(gid, 4u);
    if c.y >= pass_.lines { return; }
    let b = base(c);
    let v0 = load(b, c.x, 0u, 4u);
    let v1 = load(b, c.x, 1u, 4u);
    let v2 = load(b, c.x, 2u, 4u);
    let v3 = load(b, c.x, 3u, 4u);
    let s02 = v0 + v2;
    let d02 = v0 - v2;
    let s13 = v1 + v3;
    let d13 = rot(v1 - v3);
    store(b, c.x, 0u, 4u, s02 + s13);
    store(b, c.x, 1u, 4u, d02 + d13);
    store(b, c.x, 2u, 4u, s02 - s13);
    store(b, c.x, 3u, 4u, d02 - d13);
}

@compute @workgroup_size(64)
fn radix5(@builtin(global_invocation_id) gid: vec3<u32>) {
    let c = coords(gid, 5u);
    if c.y >= pass_.lines { return; }
    let b = base(c);
    let v0 = load(b, c.x, 0u, 5u);
    let v1 = load(b, c.x, 1u, 5u);
    let v2 = load(b, c.x, 2u, 5u);
    let v3 = load(b, c.x, 3u, 5u);
    let v4 = load(b, c.x, 4u, 5u);
    let t1 = v1 + v4;
    let t2 = v2 + v3;
    let d1 = v1 - v4;
    let d2 = v2 - v3;
    let a1 = v0 + C1 * t1 + C2 * t2;
    let a2 = v0 + C2 * t1 + C1 * t2;
    let b1 = rot(S1 * d1 + S2 * d2);
    let b2 = rot(S2 * d1 - S1 * d2);
    store(b, c.x, 0u, 5u, v0 + t1 + t2);
    store(b, c.x, 1u, 5u, a1 + b1);
    store(b, c.x, 4u, 5u, a1 - b1);
    store(b, c.x, 2u, 5u, a2 + b2);
    store(b, c.x, 3u, 5u, a2 - b2);
}
