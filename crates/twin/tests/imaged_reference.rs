//! The imaged patterns s̃_i of small experiments with the optical stages on, against checksums
//! recorded from the code before the optics chain was split into stages: the split must not
//! change a single bit. A change of the physics that is meant to change the patterns updates
//! these checksums, and says why in its commit.

use specmux_core::spectral::Library;
use specmux_twin::experiment::Experiment;
use specmux_twin::forward::Pipeline;
use specmux_twin::optics::imaging::simulate_patterns;
use specmux_twin::rig::Rig;
use specmux_twin::scene::Materials;

/// FNV-1a over the bits of the values: equal iff every value is bit-identical (up to collisions).
fn fnv(values: impl IntoIterator<Item = u64>) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for v in values {
        for b in v.to_le_bytes() {
            h ^= b as u64;
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}

fn f32s(v: &[f32]) -> impl Iterator<Item = u64> + '_ {
    v.iter().map(|x| x.to_bits() as u64)
}

/// Checksums of (imaged, display, targets, throughput to 9 digits, and grid) for a 64 × 64 experiment with
/// `sections`, and of the patterns the forward pipeline hands to the multiplexer.
fn checksums(sections: &str) -> [u64; 5] {
    let text = format!("[scene]\nsource = \"dead-leaves\"\nsize = [64, 64]\n{sections}");
    let exp = Experiment::from_toml(&text, "test.toml").unwrap();
    let lib = Library::default_root();
    let materials = Materials::load(&lib).unwrap();
    let rig = Rig::build(&exp, &lib, &materials).unwrap();
    let lights = rig.pattern_lights(&exp).unwrap();
    let set = simulate_patterns(
        &exp.rig.optics(),
        &rig.imaged_carriers,
        &lights,
        rig.width,
        rig.height,
    )
    .unwrap();
    let (sim, _) = Pipeline::build(&exp, &rig, &materials)
        .unwrap()
        .run()
        .unwrap();
    assert_eq!(
        sim.patterns.data, set.imaged.data,
        "pipeline vs simulate_patterns"
    );
    [
        fnv(f32s(&set.imaged.data)),
        fnv(f32s(&set.display.data)),
        fnv(f32s(&set.targets.data)),
        // The coherent throughput is a parallel sum whose order rayon does not fix: its last
        // bits vary from run to run, so it is compared to 9 significant digits.
        fnv(set
            .throughput
            .iter()
            .flat_map(|t| format!("{t:.8e}").into_bytes())
            .map(u64::from)),
        fnv(set.grid.iter().flat_map(|&(p, o)| [p as u64, o as u64])),
    ]
}

const CASES: [(&str, &str); 6] = [
    (
        "every optical stage, coherent, in-band feedback",
        "[rig.dmd]\nwidth = 64\nheight = 64\ndither = \"in-band-feedback\"\n[rig.fourier_filter]\nillumination = \"coherent\"\n[rig.lens]\n",
    ),
    (
        "every optical stage, incoherent, DMD larger than the field",
        "[rig.dmd]\nwidth = 72\nheight = 70\n[rig.fourier_filter]\nillumination = \"incoherent\"\n[rig.lens]\n",
    ),
    (
        "DMD and lens, no filter",
        "[rig.dmd]\nwidth = 64\nheight = 64\n[rig.lens]\n",
    ),
    ("lens alone on a grey modulator", "[rig.lens]\n"),
    (
        "filter alone on a grey modulator, coherent",
        "[rig.fourier_filter]\nillumination = \"coherent\"\n",
    ),
    (
        "DMD and a 532 nm line through the filter",
        "[rig.dmd]\nwidth = 64\nheight = 64\n[rig.fourier_filter]\nlight = \"line\"\n",
    ),
];

#[test]
fn imaged_patterns_match_the_recorded_checksums() {
    // These checksums belong to version 1 of the patterns' physics. A change meant to change
    // them records new ones and raises `imaging::MODEL` with them, so that every cached
    // pattern set of the old physics is a miss (pattern_cache.rs).
    assert_eq!(specmux_twin::optics::imaging::MODEL, 1);
    // Recorded from the code before the split (commit 76f38ec).
    let want: [[u64; 5]; 6] = [
        [
            0xc523f14ef92a9def,
            0xa634f8f34d692745,
            0x5b266fdd20df6325,
            0x335c9d35441b9ca,
            0x205e8252448af0e5,
        ],
        [
            0xf45edd9dca968191,
            0xf7788f20ba893925,
            0x41082448fa8f9225,
            0x3b017eaf914b5de7,
            0xdcce78a3d5777ce5,
        ],
        [
            0x2b6ef6ccf042eb1e,
            0x79a7848060ce6925,
            0x5b266fdd20df6325,
            0x53e02accb805cba5,
            0x9a4297133c0b8de5,
        ],
        [
            0xdd67be9c75990325,
            0x5b266fdd20df6325,
            0x5b266fdd20df6325,
            0x53e02accb805cba5,
            0x9a4297133c0b8de5,
        ],
        [
            0xe7190f43da38709d,
            0xfbcfd9b1861f6325,
            0xfbcfd9b1861f6325,
            0xa61070a53f24f86c,
            0x205e8252448af0e5,
        ],
        [
            0x13a1cae33e8f1b94,
            0xd96b7f6bf2dfb925,
            0xfbcfd9b1861f6325,
            0x47bf644cdedd064a,
            0xa5f8598262369165,
        ],
    ];
    let mut bad = Vec::new();
    for ((name, sections), want) in CASES.iter().zip(want) {
        let got = checksums(sections);
        if got != want {
            bad.push(format!("{name}: got {got:#x?}"));
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}
