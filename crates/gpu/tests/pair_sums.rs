//! The 4f-relay pair sums on the GPU against a hand-solved case and bad input (the comparison
//! with the twin's CPU `pair_sums` is in the twin, `--features gpu`, where its bins are made).

mod common;

use specmux_gpu::pair_sums::{GpuPairSums, PairBin, PassInterval};
use specmux_gpu::GpuError;

/// A bin with one interval of the given ends and cumulative weights.
fn bin(kx: i64, ky: i64, value: [f64; 2], lo: f64, c_lo: [f64; 2]) -> PairBin {
    let iv = PassInterval {
        lo,
        hi: 600.0,
        c_lo,
        c_hi: [1.0, 0.5],
    };
    PairBin {
        kx,
        ky,
        value,
        intervals: [iv, PassInterval::default(), PassInterval::default()],
        n: 1,
    }
}

/// A = (0,0) value 1 and B = (1,0) value i pass on 500–600 nm (pair weights [1, 0.5]); C = (1,1)
/// value 2 on 550–600 nm (its pairs with A, B: [1, 0.5] − [0.25, 0.1] = [0.75, 0.4]). By hand:
/// S(0,0) = 1 + 1 + 4·0.75, S(1,0) = i·1̄, S(1,1) = 2·1̄·0.75, S(0,±1) = ∓2i·0.75, S(1,−1) = 0.
#[test]
fn three_bins_give_the_hand_solved_sums() {
    let Some(ctx) = common::context() else { return };
    let bins = [
        bin(0, 0, [1.0, 0.0], 500.0, [0.0; 2]),
        bin(1, 0, [0.0, 1.0], 500.0, [0.0; 2]),
        bin(1, 1, [2.0, 0.0], 550.0, [0.25, 0.1]),
    ];
    let s = GpuPairSums::new(&ctx).run(&ctx, &bins).unwrap();
    assert_eq!((s.qx_max, s.qy_max), (1, 1));
    let at = |qx: usize, qy: i64| s.sums[qx * 3 + (qy + 1) as usize];
    let want = [
        ((0, 0), [5.0, 0.0, 2.6, 0.0]),
        ((0, 1), [0.0, -1.5, 0.0, -0.8]),
        ((0, -1), [0.0, 1.5, 0.0, 0.8]),
        ((1, 0), [0.0, 1.0, 0.0, 0.5]),
        ((1, 1), [1.5, 0.0, 0.8, 0.0]),
        ((1, -1), [0.0; 4]),
    ];
    for ((qx, qy), w) in want {
        let got = at(qx, qy);
        for (g, w) in got.iter().zip(w) {
            assert!(
                (*g as f64 - w).abs() < 1e-6,
                "({qx}, {qy}): {got:?}, want {w}"
            );
        }
    }
}

/// Unsorted bins, a bin without intervals and a NaN are shape errors naming the bin.
#[test]
fn bad_bins_are_refused_naming_the_bin() {
    let Some(ctx) = common::context() else { return };
    let k = GpuPairSums::new(&ctx);
    let a = bin(0, 0, [1.0, 0.0], 500.0, [0.0; 2]);
    let cases = [
        (vec![a, PairBin { kx: -1, ..a }], "bin 1 is not after"),
        (vec![PairBin { n: 0, ..a }], "bin 0 has 0 intervals"),
        (
            vec![
                a,
                PairBin {
                    kx: 2,
                    value: [f64::NAN, 0.0],
                    ..a
                },
            ],
            "bin 1 has a value",
        ),
    ];
    for (bins, want) in cases {
        match k.run(&ctx, &bins) {
            Err(GpuError::Shape(e)) => assert!(e.contains(want), "{e}"),
            other => panic!("{want}: {:?}", other.map(|s| s.sums.len())),
        }
    }
    let empty = k.run(&ctx, &[]).unwrap();
    assert_eq!(empty.sums, [[0.0; 4]]);
}
