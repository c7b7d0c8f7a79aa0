//! `specmux design filters`: choose the wheel's filter set from a catalogue. Every combination
//! is searched exactly (branch and bound for the paper's criterion, every combination scored for
//! the others); the best sets by each criterion are ranked, the best few simulated through the
//! twin on the scenes, their curves plotted, and the chosen set written as `[rig.wheel]`.

use crate::catalog::{self, Candidate, Families};
use crate::criteria::{Evaluator, NoiseModel, Scores, CRITERIA};
use crate::search::{self, Ranked};
use crate::{plot, scenes};
use serde::Serialize;
use specmux_core::error::check_count;
use specmux_core::interrupt;
use specmux_core::spectral::{Curve, Grid, Library};
use specmux_core::{Error, Result};
use specmux_report::plot::Colorimetry;
use specmux_report::progress;
use specmux_twin::optics::wheel::ColorWheel;
use specmux_twin::scene::Materials;
use specmux_twin::{Experiment, Rig};
use std::fmt::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Options of `specmux design filters`.
#[derive(clap::Args, Clone, Debug)]
pub struct FilterArgs {
    /// Folder searched (recursively) for transmittance CSVs; default: the spectral library.
    #[arg(long)]
    pub catalog: Option<PathBuf>,
    /// Filters per set (the wheel's segments).
    #[arg(long, default_value_t = 6)]
    pub choose: usize,
    /// Parametric families to add (TOML: gaussian_centres_nm and longpass/shortpass_edges_nm as
    /// [first, last, step], gaussian_fwhm_nm, dichroic_bands_nm, edge_width_nm, peak, floor;
    /// docs/design.md); default: the families of docs/design.md.
    #[arg(long)]
    pub families: Option<PathBuf>,
    /// Search the folder's curves only.
    #[arg(long)]
    pub no_families: bool,
    /// Curves every set must hold (library names, comma-separated), as the paper kept its dichroics.
    #[arg(long, value_delimiter = ',')]
    pub keep: Vec<String>,
    /// Light level of the noise criterion: electrons at a white target's frame peak.
    #[arg(long, default_value_t = 10000.0, allow_negative_numbers = true)]
    pub electrons: f64,
    /// Sets listed per criterion.
    #[arg(long, default_value_t = 5)]
    pub top: usize,
    /// Best sets of the paper's criterion and of the predicted RMSE simulated on the scenes.
    #[arg(long, default_value_t = 2)]
    pub simulate: usize,
    /// Experiment files whose scenes score the sets; default: every file in `--scenes-dir`.
    #[arg(long, num_args = 1..)]
    pub scenes: Vec<PathBuf>,
    /// The folder of experiment files `--scenes` defaults to.
    #[arg(long, default_value = "scenes")]
    pub scenes_dir: PathBuf,
    /// Side of procedural scenes in the simulations.
    #[arg(long, default_value_t = 256)]
    pub size: usize,
    /// Experiment giving the light, camera, band grid, basis, η and crop (default: the prototype).
    #[arg(long)]
    pub experiment: Option<PathBuf>,
    #[arg(long, default_value = "out/design-filters")]
    pub out: PathBuf,
}

/// A set simulated on every scene.
#[derive(Clone, Debug, Serialize)]
pub struct Simulated {
    pub label: String,
    pub filters: Vec<String>,
    pub scores: Option<Scores>,
    pub outcomes: Vec<scenes::Outcome>,
}

impl Simulated {
    fn mean_psnr(&self) -> f64 {
        self.outcomes.iter().map(|o| o.cube_psnr_db).sum::<f64>() / self.outcomes.len() as f64
    }
}

/// A ranked set in the report: its value under the criterion, its curves and every score.
type RankedSet<'a> = (f64, Vec<&'a str>, Scores);

/// The JSON report.
#[derive(Serialize)]
struct Report<'a> {
    catalogue: Vec<&'a str>,
    combinations: u64,
    noise: NoiseModel,
    ranked: Vec<(&'static str, Vec<RankedSet<'a>>)>,
    simulated: &'a [Simulated],
    chosen: &'a str,
    seconds: Vec<(&'static str, f64)>,
}

/// The base experiment: a file or a built-in scene's name (as every command takes them), or the
/// prototype.
pub fn base_experiment(path: Option<&Path>) -> Result<Experiment> {
    match path {
        Some(p) => specmux_report::commands::experiment_for(&p.to_string_lossy(), None),
        None => Ok(Experiment::prototype()),
    }
}

/// Most combinations the exhaustive search scores: about 0.7 M a second on two cores (3.8 M in
/// 5.3 s, docs/design.md), so five minutes.
const MAX_COMBINATIONS: u64 = 200_000_000;

/// Catalogue, rig and evaluator of a run.
struct Setup {
    cat: Vec<Candidate>,
    ev: Evaluator,
    keep: Vec<usize>,
    /// The sets the exhaustive search scores.
    combos: u64,
    range_nm: (f64, f64),
}

fn setup(a: &FilterArgs, base: &Experiment, lib: &Library) -> Result<Setup> {
    let fam = match (&a.families, a.no_families) {
        (_, true) => None,
        (Some(p), false) => Some(Families::load(p)?),
        (None, false) => Some(Families::default()),
    };
    let dir = a.catalog.clone().map_or_else(|| lib.clone(), Library::new);
    let cat = catalog::load(Some(&dir), fam.as_ref(), lib)?;
    if !(1..=16).contains(&a.choose) || a.choose > cat.len() {
        let why = format!(
            "needs 1 to 16 filters and at most the catalogue's {}",
            cat.len()
        );
        return Err(Error::config("--choose", "choose", a.choose, &why));
    }
    let keep = a
        .keep
        .iter()
        .map(|k| {
            cat.iter()
                .position(|c| &c.name == k)
                .ok_or_else(|| Error::config("--keep", "keep", k, "is not in the catalogue"))
        })
        .collect::<Result<Vec<_>>>()?;
    let combos = search::combinations(cat.len(), a.choose, &keep);
    if combos > MAX_COMBINATIONS {
        let why = format!("{combos} combinations of the catalogue's {} curves, more than {MAX_COMBINATIONS} (about five minutes on two cores): narrow the families, --keep curves or choose fewer", cat.len());
        return Err(Error::config("--choose", "choose", a.choose, &why));
    }
    // Before the search: a set of another size has no carrier layout to run on.
    let carriers = base.carrier_count();
    if a.choose != carriers {
        let why = format!("one filter per carrier: the experiment ({}) has {carriers} carriers (rig.carriers.frequencies)", base.file);
        return Err(Error::config("--choose", "choose", a.choose, &why));
    }
    let materials = Materials::load(lib)?;
    let rig = Rig::build(base, lib, &materials)?;
    let wheel = ColorWheel {
        filters: cat.iter().map(|c| c.curve.clone()).collect(),
    };
    let p = wheel.projection(&rig.grid, rig.illuminant.as_ref(), &rig.qe)?;
    let w_raw = p.w / p.scale;
    if let Some(i) = (0..cat.len()).find(|&i| !(w_raw.row(i).sum() > 0.0)) {
        let why = "passes no light on the band grid with this light and camera";
        return Err(Error::config(
            &dir.provenance(),
            "catalogue",
            &cat[i].name,
            why,
        ));
    }
    let curves: Vec<_> = cat.iter().map(|c| &c.curve).collect();
    let noise = NoiseModel {
        electrons: a.electrons,
        read_noise_e: specmux_twin::sensor::SensorConfig::default().read_noise_e,
        crop: base.reconstruct.crop,
    };
    let eta = base.reconstruct.eta / rig.grid.step_nm.powi(4);
    let ev = Evaluator::new(
        &w_raw,
        &curves,
        &rig.grid,
        &rig.basis.vectors,
        &materials.held_out,
        eta,
        noise,
    )?;
    let range_nm = (rig.grid.start_nm - 20.0, rig.grid.end_nm() + 20.0);
    Ok(Setup {
        cat,
        ev,
        keep,
        combos,
        range_nm,
    })
}

/// Run the command; returns the text to print.
pub fn run(a: &FilterArgs, lib: &Library) -> Result<String> {
    if !(a.electrons.is_finite() && a.electrons > 0.0) {
        return Err(Error::config(
            "--electrons",
            "electrons",
            a.electrons,
            "must be positive",
        ));
    }
    check_count("--top", "top", a.top, 1..=1000, "sets")?;
    // The set is chosen by simulation: none simulated would leave nothing to choose.
    check_count(
        "--simulate",
        "simulate",
        a.simulate,
        1..=a.top,
        "sets (at most --top)",
    )?;
    let t0 = Instant::now();
    let base = base_experiment(a.experiment.as_deref())?;
    let s = setup(a, &base, lib)?;
    // The scenes before the search: a bad --scenes is refused before its seconds of work.
    let scenes = scenes::load(&scenes::files(&a.scenes, &a.scenes_dir)?, Some(a.size))?;
    let t_setup = t0.elapsed().as_secs_f64();
    let t = Instant::now();
    let paper = search::minimax_correlation(&s.ev, a.choose, &s.keep, a.top);
    interrupt::check("the filter search")?;
    let t_bnb = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let bar = progress::bar("scoring every combination");
    let ranked = search::exhaustive(&s.ev, a.choose, &s.keep, a.top, &bar)?;
    bar.finish_and_clear();
    let t_all = t.elapsed().as_secs_f64();
    let combos = s.combos;
    let mut text = String::new();
    let _ = writeln!(
        text,
        "catalogue: {} curves ({} generated); {} combinations of {}{}",
        s.cat.len(),
        s.cat.iter().filter(|c| c.generated.is_some()).count(),
        combos,
        a.choose,
        if s.keep.is_empty() {
            String::new()
        } else {
            format!(", keeping {}", a.keep.join(", "))
        }
    );
    let _ = writeln!(text, "exact search: branch and bound on the paper's criterion {t_bnb:.3} s; every combination scored on all criteria {t_all:.2} s ({} threads)\n", rayon::current_num_threads());
    text += &rank_table(&s, &paper.items, &ranked);
    let t = Instant::now();
    let sims = simulate_sets(a, &base, &scenes, &s, (&paper.items, &ranked[4].items), lib)?;
    let t_sim = t.elapsed().as_secs_f64();
    let chosen = choose(&sims);
    text += &sim_table(&sims, chosen);
    let times = vec![
        ("setup", t_setup),
        ("branch_and_bound", t_bnb),
        ("exhaustive", t_all),
        ("simulation", t_sim),
        ("total", t0.elapsed().as_secs_f64()),
    ];
    text += &write_outputs(
        a,
        &s,
        &sims,
        chosen,
        &paper.items,
        &ranked,
        combos,
        &times,
        lib,
    )?;
    Ok(text)
}

/// The best sets by each criterion, with every score.
fn rank_table(s: &Setup, paper: &[Ranked], ranked: &[search::TopK]) -> String {
    let mut t = String::new();
    let name = |set: &[usize]| {
        set.iter()
            .map(|&i| s.cat[i].name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let lists = std::iter::once(("max_corr (branch and bound)", paper)).chain(
        CRITERIA
            .iter()
            .zip(ranked)
            .skip(1)
            .map(|(c, r)| (*c, r.items.as_slice())),
    );
    for (crit, items) in lists {
        let _ = writeln!(
            t,
            "best by {crit}:\n{:>4} {:>9} {:>9} {:>10} {:>12} {:>14}  set",
            "rank", "max_corr", "cond(F)", "noise gain", "library RMSE", "predicted RMSE"
        );
        for (k, r) in items.iter().enumerate() {
            let sc = s.ev.score(&r.set);
            let _ = writeln!(
                t,
                "{:>4} {:>9.4} {:>9.1} {:>10.3} {:>12.5} {:>14.5}  {}",
                k + 1,
                sc.max_corr,
                sc.cond,
                sc.noise_gain,
                sc.library_rmse,
                sc.predicted_rmse,
                name(&r.set)
            );
        }
        t.push('\n');
    }
    t
}

/// Simulate the base wheel, the paper's best sets and the predicted-RMSE best sets (`paper`,
/// `ours`) on every scene of `sc`.
fn simulate_sets(
    a: &FilterArgs,
    base: &Experiment,
    sc: &[Experiment],
    s: &Setup,
    (paper, ours): (&[Ranked], &[Ranked]),
    lib: &Library,
) -> Result<Vec<Simulated>> {
    let mut sets: Vec<(String, Vec<String>)> =
        vec![("base wheel".into(), base.rig.wheel.filters.clone())];
    let names = |set: &[usize]| {
        set.iter()
            .map(|&i| s.cat[i].name.clone())
            .collect::<Vec<_>>()
    };
    for (tag, list) in [("max_corr", paper), ("predicted_rmse", ours)] {
        for (k, r) in list.iter().take(a.simulate).enumerate() {
            sets.push((format!("{tag} #{}", k + 1), names(&r.set)));
        }
    }
    let chosen: Vec<&Candidate> = s
        .cat
        .iter()
        .filter(|c| sets.iter().any(|(_, f)| f.contains(&c.name)))
        .collect();
    let renamed = catalog::write_generated(&chosen, lib, &a.out)?;
    let bar = progress::bar("simulating sets on scenes");
    bar.set_length((sets.len() * sc.len()) as u64);
    let mut out = Vec::new();
    for (label, names) in sets {
        let idx: Option<Vec<usize>> = names
            .iter()
            .map(|f| s.cat.iter().position(|c| &c.name == f))
            .collect();
        // A curve the embedded library could not take is named by its file in --out.
        let filters: Vec<String> = (names.iter())
            .map(|f| {
                renamed
                    .iter()
                    .find(|(n, _)| n == f)
                    .map_or(f, |(_, u)| u)
                    .clone()
            })
            .collect();
        let mut outcomes = Vec::new();
        for e in sc {
            let mut e = e.clone();
            e.rig.wheel.filters = filters.clone();
            outcomes.push(scenes::simulate(&e, lib)?);
            progress::step(&bar, "simulating filter sets")?;
        }
        out.push(Simulated {
            label,
            scores: idx.map(|i| s.ev.score(&i)),
            filters,
            outcomes,
        });
    }
    bar.finish_and_clear();
    Ok(out)
}

/// The chosen set: of the predicted-RMSE sets simulated, the best mean cube PSNR over the scenes.
fn choose(sims: &[Simulated]) -> usize {
    (0..sims.len())
        .filter(|&i| sims[i].label.starts_with("predicted_rmse"))
        .max_by(|&a, &b| sims[a].mean_psnr().total_cmp(&sims[b].mean_psnr()))
        .unwrap_or(0)
}

/// Final-cube PSNR / SAM of each simulated set on each scene, and ours against the paper's.
fn sim_table(sims: &[Simulated], chosen: usize) -> String {
    let mut t =
        String::from("final cube, simulated (ideal patterns, noiseless; PSNR dB / SAM °):\n");
    let Some(first) = sims.first() else { return t };
    let _ = write!(t, "{:<18}", "set");
    for o in &first.outcomes {
        let _ = write!(t, " {:>18}", o.scene);
    }
    let _ = writeln!(t, " {:>9}", "mean dB");
    for s in sims {
        let _ = write!(t, "{:<18}", s.label);
        for o in &s.outcomes {
            let _ = write!(t, " {:>10.2} / {:>5.2}", o.cube_psnr_db, o.cube_sam_deg);
        }
        let _ = writeln!(t, " {:>9.2}", s.mean_psnr());
    }
    if let Some(p) = sims.iter().find(|s| s.label == "max_corr #1") {
        let c = &sims[chosen];
        let _ = write!(t, "\n{} − max_corr #1 (dB / °):", c.label);
        for (a, b) in c.outcomes.iter().zip(&p.outcomes) {
            let _ = write!(
                t,
                " {}: {:+.2} / {:+.2};",
                a.scene,
                a.cube_psnr_db - b.cube_psnr_db,
                a.cube_sam_deg - b.cube_sam_deg
            );
        }
        t.push('\n');
    }
    let _ = writeln!(
        t,
        "chosen: {} = {}",
        sims[chosen].label,
        sims[chosen].filters.join(", ")
    );
    t
}

/// The colour of each filter: its transmittance seen under equal-energy white (`col`, on
/// [`Grid::VISIBLE`]), at full brightness.
fn chips(curves: &[Curve], col: &Colorimetry) -> Vec<[u8; 3]> {
    (curves.iter())
        .map(|c| col.chip(&c.sample(&Grid::VISIBLE)))
        .collect()
}

/// `wheel.toml`, the curve PNGs and `report.json`; returns the lines naming them.
#[allow(clippy::too_many_arguments)]
fn write_outputs(
    a: &FilterArgs,
    s: &Setup,
    sims: &[Simulated],
    chosen: usize,
    paper: &[Ranked],
    ranked: &[search::TopK],
    combos: u64,
    seconds: &[(&'static str, f64)],
    lib: &Library,
) -> Result<String> {
    let c = &sims[chosen];
    let list: Vec<String> = c.filters.iter().map(|f| format!("\"{f}\"")).collect();
    let toml = format!(
        "# specmux design filters: {} (predicted RMSE {:.5}); paste into an experiment file\n[rig.wheel]\nfilters = [{}]\n",
        c.label,
        c.scores.map_or(f64::NAN, |x| x.predicted_rmse),
        list.join(", ")
    );
    specmux_io::atomic::write_bytes(&a.out.join("wheel.toml"), toml.as_bytes())?;
    let mut text = String::new();
    let col = Colorimetry::new(lib, &Grid::VISIBLE, None)?;
    for sim in sims
        .iter()
        .filter(|x| x.label.ends_with("#1") || x.label == c.label)
    {
        let curves: Vec<_> = sim
            .filters
            .iter()
            .map(|f| lib.curve(f))
            .collect::<Result<_>>()?;
        let file = format!("curves_{}.png", sim.label.replace([' ', '#'], ""));
        let refs: Vec<_> = curves.iter().collect();
        plot::curves(
            &a.out.join(&file),
            &format!("Filter set: {}", sim.label),
            &refs,
            &chips(&curves, &col),
            s.range_nm,
        )?;
        let _ = writeln!(text, "wrote {}", a.out.join(file).display());
    }
    let names = |set: &[usize]| {
        set.iter()
            .map(|&i| s.cat[i].name.as_str())
            .collect::<Vec<_>>()
    };
    let rank = |items: &[Ranked]| {
        items
            .iter()
            .map(|r| (r.value, names(&r.set), s.ev.score(&r.set)))
            .collect::<Vec<_>>()
    };
    let report = Report {
        catalogue: s.cat.iter().map(|c| c.name.as_str()).collect(),
        combinations: combos,
        noise: s.ev.noise,
        ranked: std::iter::once(("max_corr", rank(paper)))
            .chain(
                CRITERIA
                    .iter()
                    .zip(ranked)
                    .skip(1)
                    .map(|(n, r)| (*n, rank(&r.items))),
            )
            .collect(),
        simulated: sims,
        chosen: &c.label,
        seconds: seconds.to_vec(),
    };
    specmux_report::commands::write_report(&a.out.join("report.json"), lib, "design", &report)?;
    let _ = writeln!(
        text,
        "wrote {} and {}",
        a.out.join("wheel.toml").display(),
        a.out.join("report.json").display()
    );
    for (k, v) in seconds {
        let _ = write!(text, "{k} {v:.2} s; ");
    }
    text.push('\n');
    Ok(text)
}
