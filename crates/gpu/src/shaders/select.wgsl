// The rank-th smallest of the non-negative values v_i whose weight is non-zero, exactly, by
// a most-significant-digit radix select on their bits (a non-negative f32 orders as its bit
// pattern): four passes of 8 bits, each a histogram of the values that share the digits
// found so far and a one-workgroup scan that picks the next digit. The result's bits end in
// word 0 of `state`; the same value a sort of those values would put at `rank`.

struct Pass {
    // The digit of this pass: bits shift .. shift + 7.
    shift: u32,
    // The bits found by the earlier passes.
    mask: u32,
    // 1 for the first pass (the state is reset to prefix 0, `rank`).
    first: u32,
    rank: u32,
    n: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// ---- histogram: counts of the next digit among the candidates (workgroup-local first).
@group(0) @binding(0) var<storage, read> hs_v: array<f32>;
@group(0) @binding(1) var<storage, read> hs_weight: array<f32>;
@group(0) @binding(2) var<storage, read_write> hs_hist: array<atomic<u32>, 256>;
@group(0) @binding(3) var<storage, read> hs_state: array<u32, 2>;
@group(0) @binding(4) var<uniform> hs_p: Pass;

var<workgroup> local_hist: array<atomic<u32>, 256>;

@compute @workgroup_size(256)
fn histogram(
    @builtin(local_invocation_index) lid: u32,
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    atomicStore(&local_hist[lid], 0u);
    workgroupBarrier();
    let prefix = hs_state[0] & hs_p.mask;
    for (var i = wid.x * 256u + lid; i < hs_p.n; i += nwg.x * 256u) {
        let key = bitcast<u32>(hs_v[i]);
        if hs_weight[i] != 0.0 && (key & hs_p.mask) == prefix {
            atomicAdd(&local_hist[(key >> hs_p.shift) & 255u], 1u);
        }
    }
    workgroupBarrier();
    let c = atomicLoad(&local_hist[lid]);
    if c > 0u {
        atomicAdd(&hs_hist[lid], c);
    }
}

// ---- scan: the digit whose bucket holds the remaining rank; the histogram is left zeroed
// for the next pass.
@group(0) @binding(0) var<storage, read_write> sn_hist: array<u32, 256>;
@group(0) @binding(1) var<storage, read_write> sn_state: array<u32, 2>;
@group(0) @binding(2) var<uniform> sn_p: Pass;

var<workgroup> counts: array<u32, 256>;

@compute @workgroup_size(256)
fn scan(@builtin(local_invocation_index) lid: u32) {
    counts[lid] = sn_hist[lid];
    sn_hist[lid] = 0u;
    workgroupBarrier();
    if lid != 0u {
        return;
    }
    var prefix = sn_state[0];
    var rank = sn_state[1];
    if sn_p.first == 1u {
        prefix = 0u;
        rank = sn_p.rank;
    }
    var below = 0u;
    var digit = 0u;
    loop {
        let c = counts[digit];
        if below + c > rank || digit == 255u {
            break;
        }
        below += c;
        digit++;
    }
    sn_state[0] = prefix | (digit << sn_p.shift);
    sn_state[1] = rank - below;
}
