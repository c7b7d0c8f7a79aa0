// The 4f relay's pair sums (crates/twin/src/optics/relay.rs: pair_sums) for one output cell
// per invocation: S(q) = Σ value_a·conj(value_b)·overlap(a, b) over the bins with
// k_a − k_b = q, qx ≥ 0; components (S0.re, S0.im, S1.re, S1.im).
//
// The bins are sorted by (kx, ky) and cut into runs of consecutive ky in one column; for a cell
// the pairs are the overlaps of a run of column kx_a with a run of column kx_a − qx shifted by
// qy, found by merging the two columns' runs, so no pair is visited that cannot contribute. Interval ends are ranks of the host's f64
// values (the same comparisons as the CPU); cumulative weights come as f32 (hi, lo) splits so
// that their difference keeps f32 precision relative to itself. Each column's pairs are summed
// plainly, the columns with Kahan compensation. A dispatch covers one chunk of columns kx_a and
// one window of rows ky_a (lavapipe ends long loops early, so no invocation runs over all
// columns, nor along a whole long run): the running sum and its compensation stay in `sums`
// between the dispatches.

struct Interval {
    lo: u32,
    hi: u32,
    _pad0: u32,
    _pad1: u32,
    // Cumulative (weight hi, weight lo, moment hi, moment lo) below lo and through hi.
    c_lo: vec4<f32>,
    c_hi: vec4<f32>,
}

struct Bin {
    value: vec2<f32>,
    n: u32,
    _pad: u32,
    iv: array<Interval, 3>,
}

struct Params {
    ncols: u32,
    qy_max: u32,
    ncells: u32,
    // First column kx_a − kx0 of this dispatch's chunk; it ends at ca0 + CHUNK.
    ca0: u32,
    // First row ky_a of this dispatch's window; it ends at ka0 + ROWS.
    ka0: i32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

const CHUNK: u32 = 64u;
const ROWS: i32 = 256;

@group(0) @binding(0) var<storage, read> bins: array<Bin>;
// Per run: (first ky, length, index of its first bin, unused).
@group(0) @binding(1) var<storage, read> runs: array<vec4<i32>>;
// Runs of column c (kx = kx0 + c) are runs[cols[c]] .. runs[cols[c + 1]].
@group(0) @binding(2) var<storage, read> cols: array<u32>;
// Per cell: the sum at 2·cell, its Kahan compensation at 2·cell + 1.
@group(0) @binding(3) var<storage, read_write> sums: array<vec4<f32>>;
@group(0) @binding(4) var<uniform> pp: Params;

// ∫ of the pair weights over the wavelengths for which both bins pass (relay.rs: overlap).
fn overlap(a: u32, b: u32) -> vec2<f32> {
    var g = vec2<f32>(0.0);
    for (var i = 0u; i < bins[a].n; i++) {
        let x = bins[a].iv[i];
        for (var j = 0u; j < bins[b].n; j++) {
            let y = bins[b].iv[j];
            var lo = y.lo;
            var c_lo = y.c_lo;
            if x.lo >= y.lo {
                lo = x.lo;
                c_lo = x.c_lo;
            }
            var hi = y.hi;
            var c_hi = y.c_hi;
            if x.hi <= y.hi {
                hi = x.hi;
                c_hi = x.c_hi;
            }
            if hi >= lo {
                g += (c_hi.xz - c_lo.xz) + (c_hi.yw - c_lo.yw);
            }
        }
    }
    return g;
}

// Σ over the pairs of run ra (column kx_a) and run rb (column kx_a − qx) at this qy, with ky_a
// in this dispatch's window.
fn run_pairs(ra: vec4<i32>, rb: vec4<i32>, qy: i32) -> vec4<f32> {
    var acc = vec4<f32>(0.0);
    let lo = max(max(ra.x, rb.x + qy), pp.ka0);
    let hi = min(min(ra.x + ra.y, rb.x + rb.y + qy), pp.ka0 + ROWS);
    for (var ky = lo; ky < hi; ky++) {
        let a = u32(ra.z + ky - ra.x);
        let b = u32(rb.z + ky - qy - rb.x);
        let g = overlap(a, b);
        if all(g == vec2<f32>(0.0)) {
            continue;
        }
        let va = bins[a].value;
        let vb = bins[b].value;
        let p = vec2<f32>(va.x * vb.x + va.y * vb.y, va.y * vb.x - va.x * vb.y);
        acc += vec4<f32>(p * g.x, p * g.y);
    }
    return acc;
}

// The first run in runs[r0..r1) (sorted, disjoint) that ends, shifted by `shift`, after row y.
fn first_ending_after(r0: u32, r1: u32, shift: i32, y: i32) -> u32 {
    var lo = r0;
    var hi = r1;
    while lo < hi {
        let mid = (lo + hi) / 2u;
        let r = runs[mid];
        if r.x + r.y + shift > y {
            hi = mid;
        } else {
            lo = mid + 1u;
        }
    }
    return lo;
}

// Σ over the pairs of column ca and column cb shifted by qy, with ky_a in this dispatch's
// window: the two sorted run lists are merged, so only runs that meet are paired (a column of
// many short runs would otherwise pair every run with every other).
fn column_pairs(ca: u32, cb: u32, qy: i32) -> vec4<f32> {
    var part = vec4<f32>(0.0);
    let end = pp.ka0 + ROWS;
    var i = first_ending_after(cols[ca], cols[ca + 1u], 0, pp.ka0);
    var j = first_ending_after(cols[cb], cols[cb + 1u], qy, pp.ka0);
    while i < cols[ca + 1u] && j < cols[cb + 1u] {
        let ra = runs[i];
        let rb = runs[j];
        if ra.x >= end || rb.x + qy >= end {
            break;
        }
        part += run_pairs(ra, rb, qy);
        // The run that ends first meets nothing further on.
        if ra.x + ra.y <= rb.x + rb.y + qy {
            i++;
        } else {
            j++;
        }
    }
    return part;
}

@compute @workgroup_size(64)
fn pair_sums(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let cell = gid.x + gid.y * nwg.x * 64u;
    if cell >= pp.ncells {
        return;
    }
    let h = 2u * pp.qy_max + 1u;
    let qx = cell / h;
    let qy = i32(cell % h) - i32(pp.qy_max);
    var sum = sums[2u * cell];
    var comp = sums[2u * cell + 1u];
    for (var ca = max(qx, pp.ca0); ca < min(pp.ncols, pp.ca0 + CHUNK); ca++) {
        let cb = ca - qx;
        let part = column_pairs(ca, cb, qy);
        // Kahan: comp carries what the last addition lost.
        let y = part - comp;
        let t = sum + y;
        comp = (t - sum) - y;
        sum = t;
    }
    sums[2u * cell] = sum;
    sums[2u * cell + 1u] = comp;
}
