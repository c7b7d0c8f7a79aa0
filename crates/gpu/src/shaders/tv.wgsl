// Chambolle's dual projection for vectorial TV denoising (crates/core/src/tv.rs does the
// same on the CPU): u = argmin ½‖u − f‖² + λ Σ_p (Σ_k |∇u_k(p)|²)^½, forward differences with
// Neumann boundaries, the dual field (px, py) warm-started across calls. λ is read from
// word 1 of `lam` (a list written on the GPU: count, then values); λ ≤ 0 leaves f as it is.

struct Params {
    w: u32,
    h: u32,
    planes: u32,
    _pad: u32,
}

// The step (core::tv::TAU; specmux-gpu writes its value here).
const TAU: f32 = 0.25;

@group(0) @binding(0) var<storage, read_write> f: array<f32>;
@group(0) @binding(1) var<storage, read_write> px: array<f32>;
@group(0) @binding(2) var<storage, read_write> py: array<f32>;
@group(0) @binding(3) var<storage, read_write> g: array<f32>;
@group(0) @binding(4) var<storage, read> lam: array<f32, 2>;
@group(0) @binding(5) var<uniform> tp: Params;

fn lambda() -> f32 {
    return lam[1];
}

// div p = −∇ᵀp at (x, y) of the plane starting at `base`.
fn divergence(base: u32, x: u32, y: u32) -> f32 {
    let p = base + y * tp.w + x;
    var dx = 0.0;
    if x + 1u < tp.w { dx = px[p]; }
    if x > 0u { dx -= px[p - 1u]; }
    var dy = 0.0;
    if y + 1u < tp.h { dy = py[p]; }
    if y > 0u { dy -= py[p - tp.w]; }
    return dx + dy;
}

// Forward differences of g at (x, y), 0 across the last column and row.
fn gradient(base: u32, x: u32, y: u32) -> vec2<f32> {
    let p = base + y * tp.w + x;
    var d = vec2<f32>(0.0, 0.0);
    if x + 1u < tp.w { d.x = g[p + 1u] - g[p]; }
    if y + 1u < tp.h { d.y = g[p + tp.w] - g[p]; }
    return d;
}

fn outside(gid: vec3<u32>) -> bool {
    return gid.x >= tp.w || gid.y >= tp.h || lambda() <= 0.0;
}

// Invocation (x, y, plane): g = div p − f/λ.
@compute @workgroup_size(16, 16)
fn tv_g(@builtin(global_invocation_id) gid: vec3<u32>) {
    if outside(gid) { return; }
    let base = gid.z * tp.w * tp.h;
    let p = base + gid.y * tp.w + gid.x;
    g[p] = divergence(base, gid.x, gid.y) - f[p] * (1.0 / lambda());
}

// Invocation (x, y): p ← (p + τ∇g) / (1 + τ|∇g|), |∇g| joint over the planes.
@compute @workgroup_size(16, 16)
fn tv_dual(@builtin(global_invocation_id) gid: vec3<u32>) {
    if outside(gid) { return; }
    let npx = tp.w * tp.h;
    var m = 0.0;
    for (var k = 0u; k < tp.planes; k++) {
        let d = gradient(k * npx, gid.x, gid.y);
        m += d.x * d.x + d.y * d.y;
    }
    let s = 1.0 / (1.0 + TAU * sqrt(m));
    for (var k = 0u; k < tp.planes; k++) {
        let d = gradient(k * npx, gid.x, gid.y);
        let p = k * npx + gid.y * tp.w + gid.x;
        px[p] = (px[p] + TAU * d.x) * s;
        py[p] = (py[p] + TAU * d.y) * s;
    }
}

// Invocation (x, y, plane): f ← f − λ·div p.
@compute @workgroup_size(16, 16)
fn tv_out(@builtin(global_invocation_id) gid: vec3<u32>) {
    if outside(gid) { return; }
    let base = gid.z * tp.w * tp.h;
    let p = base + gid.y * tp.w + gid.x;
    f[p] -= lambda() * divergence(base, gid.x, gid.y);
}
