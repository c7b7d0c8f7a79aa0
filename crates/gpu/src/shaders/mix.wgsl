// x_i = Σ_k M_ik z_k per pixel (the crosstalk inverse after de-aliasing; core Cube::mix).

struct Params {
    npx: u32,
    planes_in: u32,
    planes_out: u32,
    _pad: u32,
}

@group(0) @binding(0) var<storage, read> z: array<f32>;
@group(0) @binding(1) var<storage, read_write> x: array<f32>;
@group(0) @binding(2) var<storage, read> m: array<f32>;
@group(0) @binding(3) var<uniform> mp: Params;

@compute @workgroup_size(256)
fn mix(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let n = mp.npx;
    let p = gid.x + gid.y * nwg.x * 256u;
    if p >= n {
        return;
    }
    for (var i = 0u; i < mp.planes_out; i++) {
        var acc = 0.0;
        for (var k = 0u; k < mp.planes_in; k++) {
            acc += m[i * mp.planes_in + k] * z[k * n + p];
        }
        x[i * n + p] = acc;
    }
}
