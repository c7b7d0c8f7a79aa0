//! The architecture, checked from the source text: inside each crate the files import one
//! another without cycles, and the top-level modules import only upstream along the light path
//! (the layers below); the reconstruction core depends on no simulator, plotting or codec crate.
//!
//! `use` lines and paths written inline (`crate::a::f(…)`) are read. Ignored: `pub use` (a re-export is a facade, not a dependency),
//! files named `tests.rs`, and a file's test module (everything from the first line that starts
//! with `#[cfg(test)]`, or only the declaration when that line is followed by `mod name;`).
//! `use crate::a::b::C` is an edge to the file of the longest existing module prefix (`a/b.rs`,
//! `a/b/mod.rs`, else `a.rs` …); when `C` is a name that file re-exports with `pub use`, the edge
//! follows the re-export to the file that defines it (so `crate::Cube` reaches `cube.rs`, not
//! `lib.rs`). `super::` and `self::` resolve relative to the importing file's module.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};

/// The layers of each crate's top-level modules, from upstream to downstream along the light
/// path. A module may import modules of earlier layers, and itself; never a later layer, and
/// never another module of its own layer.
const LAYERS: &[(&str, &[&[&str]])] = &[
    (
        "core",
        &[
            &["error", "pages"],
            &["cube", "spectral", "interrupt", "dead_leaves"],
            &["fft"],
            &["fft_backend"],
            &["carriers"],
            &["calibration"],
            &["demux", "noise"],
            &["crosstalk"],
            &["wavelet", "tv", "denoise"],
            &["gap"],
            &["unmix"],
            &["joint"],
            &["auto"],
            &["reconstructor"],
            &["metrics"],
        ],
    ),
    (
        "io",
        &[
            &["atomic"],
            &["exr", "png", "json", "output_set", "npy", "toml_file"],
            &["frame"],
        ],
    ),
    (
        "twin",
        // The compute device the GPU stages share, the light path, the multiplex and the cache of
        // the optics' patterns, then the calibration captures made with it and the bench report
        // auto may read; experiment composes the section configs of all of these; rig, forward
        // and run consume it.
        &[
            &["device"],
            &["scene"],
            &["optics"],
            &["timing"],
            &["sensor"],
            &["multiplex", "pattern_cache"],
            &["captures"],
            &["auto_table"],
            &["experiment"],
            &["budget"],
            &["rig"],
            &["forward"],
            &["run"],
        ],
    ),
    (
        "controller",
        // The devices, the pictures the DMD is given and the plan, then the simulated and real
        // devices that follow them, the run that drives them, its recording, and the commands.
        &[
            &["error"],
            &["log"],
            &["devices"],
            &["patterns"],
            &["plan"],
            &["ome"],
            &["real"],
            &["sim"],
            &["run"],
            &["record"],
            &["reconstruct", "trigger_chain"],
            &["commands"],
        ],
    ),
    (
        "design",
        // Catalogues and layouts, the criteria and searches over them, then the two commands.
        &[
            &["catalog"],
            &["layout"],
            &["small"],
            &["criteria"],
            &["search"],
            &["leak"],
            &["scenes"],
            &["plot"],
            &["filters"],
            &["optimise"],
            &["carriers"],
        ],
    ),
    (
        "gpu",
        // The device, then the kernels in the order the reconstruction runs them.
        &[
            &["error"],
            &["context"],
            &["backend"],
            &["fft"],
            &["fft_backend"],
            &["demux"],
            &["wavelet", "select", "tv", "mix", "multiplex", "pair_sums"],
            &["gap"],
            &["unmix", "joint"],
            &["reconstructor"],
        ],
    ),
    (
        "report",
        &[
            &["plot", "progress"],
            &["panel"],
            &["bench", "sweep", "patterns", "timeline", "ptc"],
            &["commands"],
        ],
    ),
    // The Python bindings: the exception, the conversions at the boundary, the experiment and
    // the calibration-frame dicts, then one module per group of functions.
    (
        "python",
        &[
            &["error"],
            &["convert", "toml_value"],
            &["experiment", "calibration"],
            &["simulate", "reconstruct", "design", "rehearse"],
        ],
    ),
];

/// Import cycles that are known and kept, each with its reason: (crate, the module whose files
/// the cycle stays within, why). The test fails on any other cycle, and on an entry no cycle
/// matches any more (so the list cannot outlive what it excuses).
const KNOWN_CYCLES: &[(&str, &str, &str)] = &[(
    "controller",
    "sim",
    "one discrete-event bench: `Bench` (sim/mod.rs) holds the three simulated devices, and each \
     device's file adds the bench's handlers for its events (`impl Bench`), which read the other \
     devices' state; splitting them needs the devices to talk through events only",
)];

/// Crates that `crates/core` must not depend on.
const FORBIDDEN_IN_CORE: &[&str] = &[
    "specmux-twin",
    "specmux-io",
    "specmux-report",
    "plotters",
    "image",
    "exr",
];

/// A module path inside a crate: `[]` is the crate root, `["optics", "imaging"]` is `optics::imaging`.
type ModPath = Vec<String>;

/// One `use` statement: where it is, its text, and whether it is a `pub use` re-export.
struct UseStmt {
    line: usize,
    text: String,
    is_pub: bool,
    /// A path named in code (`child::Type` in a field), not a `use` line.
    inline: bool,
}

/// One source file of a crate, as a module.
struct SourceFile {
    module: ModPath,
    path: PathBuf,
    uses: Vec<UseStmt>,
}

/// One crate: its directory name and its source files keyed by module path.
struct Crate {
    name: String,
    files: BTreeMap<ModPath, SourceFile>,
}

/// One import that resolved to another file of the same crate.
struct Edge {
    from: ModPath,
    to: ModPath,
    line: usize,
    text: String,
}

/// The workspace root (the root package's directory).
fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every crate under `crates/*/src`, sorted by name.
fn crates() -> Vec<Crate> {
    let mut dirs: Vec<PathBuf> = fs::read_dir(root().join("crates"))
        .expect("read crates/")
        .map(|e| e.expect("crates/ entry").path())
        .filter(|p| p.join("src").is_dir())
        .collect();
    dirs.sort();
    dirs.iter().map(|d| load_crate(d)).collect()
}

/// Reads the source files of the crate in `dir`.
fn load_crate(dir: &Path) -> Crate {
    let src = dir.join("src");
    let mut paths = Vec::new();
    collect_rs(&src, &mut paths);
    let mut files = BTreeMap::new();
    for path in paths {
        if path.file_name().is_some_and(|n| n == "tests.rs") {
            continue;
        }
        let Some(module) = module_of(&src, &path) else {
            continue;
        };
        let text = fs::read_to_string(&path).expect("read source file");
        let uses = use_statements(&text);
        files.insert(module.clone(), SourceFile { module, path, uses });
    }
    let name = dir.file_name().unwrap().to_string_lossy().into_owned();
    Crate { name, files }
}

/// Collects every `.rs` file under `dir`, recursively.
fn collect_rs(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in fs::read_dir(dir).expect("read source dir") {
        let path = entry.expect("source dir entry").path();
        if path.is_dir() {
            collect_rs(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The module path of a source file (`lib.rs` → root, `a/mod.rs` and `a.rs` → `a`); none for `main.rs`/`bin`.
fn module_of(src: &Path, path: &Path) -> Option<ModPath> {
    let rel = path.strip_prefix(src).ok()?.with_extension("");
    let mut parts: ModPath = rel
        .iter()
        .map(|s| s.to_string_lossy().into_owned())
        .collect();
    if parts.first().is_some_and(|p| p == "bin") || parts == ["main"] {
        return None;
    }
    if parts == ["lib"] || parts.last().is_some_and(|p| p == "mod") {
        parts.pop();
    }
    Some(parts)
}

/// The `use` statements of a file outside its test module, multi-line ones joined.
fn use_statements(text: &str) -> Vec<UseStmt> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        if lines[i].starts_with("#[cfg(test)]") {
            let next = lines[i + 1..].iter().find(|l| !l.trim().is_empty());
            if next.is_some_and(|l| is_mod_declaration(l)) {
                i += 2;
                continue;
            }
            break;
        }
        let Some((is_pub, body)) = use_start(lines[i]) else {
            for path in inline_paths(lines[i]) {
                out.push(UseStmt {
                    line: i + 1,
                    text: path,
                    is_pub: false,
                    inline: true,
                });
            }
            i += 1;
            continue;
        };
        let start = i;
        let mut joined = strip_comment(body).to_string();
        while !joined.contains(';') && i + 1 < lines.len() {
            i += 1;
            joined.push(' ');
            joined.push_str(strip_comment(lines[i]));
        }
        i += 1;
        let stmt = joined.split(';').next().unwrap().trim().to_string();
        if is_path_text(&stmt) {
            out.push(UseStmt {
                line: start + 1,
                text: stmt,
                is_pub,
                inline: false,
            });
        }
    }
    out
}

/// The paths a line of code names inline (`crate::a::f(…)`, `super::b::C`, `child::D` for a
/// child module of the file): dependencies as real as a `use`. Every `name::…` path is taken;
/// `resolve` keeps those that start at `crate`, `super`, `self` or a child module.
fn inline_paths(line: &str) -> Vec<String> {
    let code = strip_comment(line);
    let is_path_char = |c: char| c.is_alphanumeric() || c == '_' || c == ':';
    let mut out = Vec::new();
    let mut rest = code;
    while let Some(i) = rest.find("::") {
        let start = rest[..i]
            .rfind(|c: char| !is_path_char(c))
            .map_or(0, |k| k + 1);
        let tail = &rest[start..];
        let end = tail.find(|c: char| !is_path_char(c)).unwrap_or(tail.len());
        let path = tail[..end].trim_end_matches(':');
        if !path.starts_with(':') && path.contains("::") {
            out.push(path.to_string());
        }
        rest = &tail[end..];
    }
    out
}

/// Whether a line is a file-module declaration such as `mod tests;`.
fn is_mod_declaration(line: &str) -> bool {
    let t = line.trim();
    t.starts_with("mod ") && t.ends_with(';') && !t.contains('{')
}

/// If the line starts a `use` statement: whether it is `pub`, and the text after `use `.
fn use_start(line: &str) -> Option<(bool, &str)> {
    let t = line.trim_start();
    if let Some(rest) = t.strip_prefix("use ") {
        return Some((false, rest));
    }
    let rest = t.strip_prefix("pub")?;
    let rest = match rest.strip_prefix('(') {
        Some(r) => &r[r.find(')')? + 1..],
        None => rest,
    };
    rest.trim_start().strip_prefix("use ").map(|r| (true, r))
}

/// The line without a trailing `//` comment.
fn strip_comment(line: &str) -> &str {
    line.find("//").map_or(line, |i| &line[..i])
}

/// Whether the text is made only of path characters (so a `use` inside a string is skipped).
fn is_path_text(s: &str) -> bool {
    !s.is_empty()
        && s.chars()
            .all(|c| c.is_alphanumeric() || c.is_whitespace() || "_:{},*".contains(c))
}

/// One path a `use` tree names, with its `as` alias (a glob keeps its final `*`, `self` is dropped).
type UsePath = (Vec<String>, Option<String>);

/// The paths a `use` tree names, groups expanded.
fn expand_use(tree: &str) -> Vec<UsePath> {
    let collapsed = tree.split_whitespace().collect::<Vec<_>>().join(" ");
    let compact: String = collapsed.replace(" as ", "@").replace(' ', "");
    let mut out = Vec::new();
    expand_into(&compact, &mut Vec::new(), &mut out);
    out
}

/// Expands `tree` under `prefix` into `out`.
fn expand_into(tree: &str, prefix: &mut Vec<String>, out: &mut Vec<UsePath>) {
    let Some(open) = tree.find('{') else {
        let (leaf, alias) = match tree.split_once('@') {
            Some((l, a)) => (l, Some(a.to_string())),
            None => (tree, None),
        };
        let mut path = prefix.clone();
        path.extend(leaf.split("::").filter(|s| !s.is_empty()).map(String::from));
        if path.last().is_some_and(|s| s == "self") {
            path.pop();
        }
        if !path.is_empty() {
            out.push((path, alias));
        }
        return;
    };
    let close = tree.rfind('}').expect("unbalanced braces in use statement");
    let head = tree[..open]
        .split("::")
        .filter(|s| !s.is_empty())
        .map(String::from);
    let depth = prefix.len();
    prefix.extend(head);
    for item in split_top_level(&tree[open + 1..close]) {
        expand_into(item, prefix, out);
    }
    prefix.truncate(depth);
}

/// Splits a group's contents at the commas that are not inside a nested group.
fn split_top_level(s: &str) -> Vec<&str> {
    let (mut depth, mut start, mut parts) = (0, 0, Vec::new());
    for (i, c) in s.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(&s[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&s[start..]);
    parts.into_iter().filter(|p| !p.is_empty()).collect()
}

/// The file an import path reaches from module `from`, or none for another crate.
fn resolve(krate: &Crate, from: &ModPath, path: &[String]) -> Option<ModPath> {
    resolve_depth(krate, from, path, 0)
}

/// `resolve`, following at most a few re-exports.
fn resolve_depth(krate: &Crate, from: &ModPath, path: &[String], depth: usize) -> Option<ModPath> {
    let (mut cur, rest) = base_of(krate, from, path)?;
    let mut consumed = 0;
    while consumed < rest.len() {
        let mut next = cur.clone();
        next.push(rest[consumed].clone());
        if !krate.files.contains_key(&next) {
            break;
        }
        cur = next;
        consumed += 1;
    }
    let remaining = &rest[consumed..];
    if let (Some(name), true) = (remaining.first(), depth < 8) {
        if let Some(target) = reexport(krate, &cur, name) {
            let mut full = target;
            full.extend(remaining[1..].iter().cloned());
            if let Some(found) = resolve_depth(krate, &cur, &full, depth + 1) {
                return Some(found);
            }
        }
    }
    Some(cur)
}

/// Where a path starts (`crate`, `super`, `self` or a child module of `from`) and the segments after it.
fn base_of<'a>(
    krate: &Crate,
    from: &ModPath,
    path: &'a [String],
) -> Option<(ModPath, &'a [String])> {
    let first = path.first()?.as_str();
    match first {
        "crate" => Some((Vec::new(), &path[1..])),
        "self" => Some((from.clone(), &path[1..])),
        "super" => {
            let mut base = from.clone();
            let mut i = 0;
            while path.get(i).is_some_and(|s| s == "super") {
                base.pop()?;
                i += 1;
            }
            Some((base, &path[i..]))
        }
        child => {
            let mut module = from.clone();
            module.push(child.to_string());
            krate
                .files
                .contains_key(&module)
                .then(|| (from.clone(), path))
        }
    }
}

/// The path (relative to `module`) of `name` when `module`'s file re-exports it with `pub use`.
fn reexport(krate: &Crate, module: &ModPath, name: &str) -> Option<Vec<String>> {
    let file = krate.files.get(module)?;
    let stmts = file.uses.iter().filter(|u| u.is_pub);
    stmts
        .flat_map(|u| expand_use(&u.text))
        .find_map(|(path, alias)| {
            let exported = alias.or_else(|| path.last().cloned())?;
            (exported == name && exported != "*").then_some(path)
        })
}

/// The imports of one crate that reach another of its files (self-edges and `pub use` left out).
fn edges(krate: &Crate) -> Vec<Edge> {
    let mut out = Vec::new();
    for file in krate.files.values() {
        for stmt in file.uses.iter().filter(|u| !u.is_pub) {
            for (mut path, _) in expand_use(&stmt.text) {
                if path.last().is_some_and(|s| s == "*") {
                    path.pop();
                }
                let Some(to) = resolve(krate, &file.module, &path) else {
                    continue;
                };
                if to != file.module {
                    out.push(Edge {
                        from: file.module.clone(),
                        to,
                        line: stmt.line,
                        text: match stmt.inline {
                            true => format!("`{}` (named in code)", stmt.text),
                            false => format!("use {};", stmt.text),
                        },
                    });
                }
            }
        }
    }
    out
}

/// A module path as Rust writes it (`crate` for the root).
fn show(module: &ModPath) -> String {
    if module.is_empty() {
        "crate".to_string()
    } else {
        module.join("::")
    }
}

/// The file of a module, relative to the workspace root.
fn file_of(krate: &Crate, module: &ModPath) -> String {
    let path = &krate.files[module].path;
    path.strip_prefix(root())
        .unwrap_or(path)
        .display()
        .to_string()
}

/// `file:line: import` for one edge.
fn cite(krate: &Crate, edge: &Edge) -> String {
    format!(
        "{}:{}: {}",
        file_of(krate, &edge.from),
        edge.line,
        edge.text
    )
}

/// The strongly connected components of a graph with more than one node (Tarjan).
fn cycles_of(graph: &BTreeMap<ModPath, BTreeSet<ModPath>>) -> Vec<Vec<ModPath>> {
    struct State<'g> {
        graph: &'g BTreeMap<ModPath, BTreeSet<ModPath>>,
        index: BTreeMap<&'g ModPath, usize>,
        low: BTreeMap<&'g ModPath, usize>,
        stack: Vec<&'g ModPath>,
        on_stack: BTreeSet<&'g ModPath>,
        out: Vec<Vec<ModPath>>,
    }
    /// Tarjan's visit of one node.
    fn visit<'g>(s: &mut State<'g>, v: &'g ModPath) {
        let n = s.index.len();
        s.index.insert(v, n);
        s.low.insert(v, n);
        s.stack.push(v);
        s.on_stack.insert(v);
        for w in s.graph.get(v).into_iter().flatten() {
            if !s.index.contains_key(w) {
                visit(s, w);
                let lw = s.low[w];
                let lv = s.low.get_mut(v).unwrap();
                *lv = (*lv).min(lw);
            } else if s.on_stack.contains(w) {
                let iw = s.index[w];
                let lv = s.low.get_mut(v).unwrap();
                *lv = (*lv).min(iw);
            }
        }
        if s.low[v] == s.index[v] {
            let mut component = Vec::new();
            loop {
                let w = s.stack.pop().unwrap();
                s.on_stack.remove(w);
                component.push(w.clone());
                if w == v {
                    break;
                }
            }
            if component.len() > 1 {
                component.sort();
                s.out.push(component);
            }
        }
    }
    let mut s = State {
        graph,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        out: Vec::new(),
    };
    for v in graph.keys() {
        if !s.index.contains_key(v) {
            visit(&mut s, v);
        }
    }
    s.out
}

/// A shortest cycle through `start` inside `component` (breadth-first), as the list of its nodes.
fn shortest_cycle(
    graph: &BTreeMap<ModPath, BTreeSet<ModPath>>,
    component: &[ModPath],
    start: &ModPath,
) -> Vec<ModPath> {
    let inside: BTreeSet<&ModPath> = component.iter().collect();
    let mut parent: BTreeMap<&ModPath, &ModPath> = BTreeMap::new();
    let mut queue = VecDeque::from([start]);
    while let Some(v) = queue.pop_front() {
        for w in graph
            .get(v)
            .into_iter()
            .flatten()
            .filter(|w| inside.contains(w))
        {
            if w == start {
                let mut path = vec![v.clone()];
                let mut cur = v;
                while cur != start {
                    cur = parent[cur];
                    path.push(cur.clone());
                }
                path.reverse();
                return path;
            }
            if !parent.contains_key(w) && w != start {
                parent.insert(w, v);
                queue.push_back(w);
            }
        }
    }
    vec![start.clone()]
}

/// The directed graph of distinct edges, every file a node.
fn graph_of(krate: &Crate, edges: &[Edge]) -> BTreeMap<ModPath, BTreeSet<ModPath>> {
    let mut graph: BTreeMap<ModPath, BTreeSet<ModPath>> = krate
        .files
        .keys()
        .map(|m| (m.clone(), BTreeSet::new()))
        .collect();
    for e in edges {
        graph.get_mut(&e.from).unwrap().insert(e.to.clone());
    }
    graph
}

/// The first edge from `a` to `b`.
fn edge_between<'e>(edges: &'e [Edge], a: &ModPath, b: &ModPath) -> &'e Edge {
    edges.iter().find(|e| &e.from == a && &e.to == b).unwrap()
}

/// Prints how many files and imports were checked.
fn print_summary(all: &[(Crate, Vec<Edge>)]) {
    for (krate, edges) in all {
        let distinct: BTreeSet<(&ModPath, &ModPath)> =
            edges.iter().map(|e| (&e.from, &e.to)).collect();
        println!(
            "crate {}: {} files, {} imports, {} distinct file edges",
            krate.name,
            krate.files.len(),
            edges.len(),
            distinct.len()
        );
    }
}

/// Every crate with its edges.
fn crates_with_edges() -> Vec<(Crate, Vec<Edge>)> {
    let all: Vec<(Crate, Vec<Edge>)> = crates()
        .into_iter()
        .map(|k| {
            let e = edges(&k);
            (k, e)
        })
        .collect();
    assert!(!all.is_empty(), "no crates found under crates/*/src");
    print_summary(&all);
    all
}

/// Rule 1: no crate has an import cycle between its files.
/// The entry of [`KNOWN_CYCLES`] that keeps this cycle of `krate`, if one does: every module of
/// the cycle lies within the entry's module.
fn known_cycle(krate: &Crate, component: &[ModPath]) -> Option<usize> {
    KNOWN_CYCLES.iter().position(|(name, within, _)| {
        *name == krate.name
            && component
                .iter()
                .all(|m| m.first().is_some_and(|t| t == within))
    })
}

#[test]
fn no_import_cycle_between_the_files_of_a_crate() {
    let mut report = String::new();
    let mut kept = BTreeSet::new();
    for (krate, edges) in crates_with_edges() {
        let graph = graph_of(&krate, &edges);
        for component in cycles_of(&graph) {
            if let Some(k) = known_cycle(&krate, &component) {
                kept.insert(k);
                continue;
            }
            let files: Vec<String> = component.iter().map(|m| file_of(&krate, m)).collect();
            let cycle = shortest_cycle(&graph, &component, &component[0]);
            let names: Vec<String> = cycle.iter().chain([&cycle[0]]).map(show).collect();
            let _ = writeln!(
                report,
                "import cycle in crate {}: {}",
                krate.name,
                names.join(" → ")
            );
            for (i, from) in cycle.iter().enumerate() {
                let to = &cycle[(i + 1) % cycle.len()];
                let _ = writeln!(
                    report,
                    "    {}",
                    cite(&krate, edge_between(&edges, from, to))
                );
            }
            let _ = writeln!(report, "  files in the cycle: {}", files.join(", "));
        }
    }
    for (k, (name, within, _)) in KNOWN_CYCLES.iter().enumerate() {
        if !kept.contains(&k) {
            let _ = writeln!(
                report,
                "KNOWN_CYCLES lists a cycle within {name}::{within} that is gone: remove the entry"
            );
        }
    }
    assert!(report.is_empty(), "\n{report}");
}

/// The layer index of each top-level module of a crate, or `None` when the crate has no layers.
fn layer_map(crate_name: &str) -> Option<BTreeMap<&'static str, usize>> {
    let (_, layers) = LAYERS.iter().find(|(name, _)| *name == crate_name)?;
    let mut map = BTreeMap::new();
    for (i, layer) in layers.iter().enumerate() {
        for module in layer.iter() {
            map.insert(*module, i);
        }
    }
    Some(map)
}

/// Problems with a crate's layer list itself: modules missing from it, entries naming no module.
fn layer_list_problems(krate: &Crate, layers: &BTreeMap<&str, usize>) -> Vec<String> {
    let tops: BTreeSet<&str> = krate
        .files
        .keys()
        .filter_map(|m| m.first())
        .map(String::as_str)
        .collect();
    let mut out = Vec::new();
    for top in &tops {
        if !layers.contains_key(top) {
            out.push(format!(
                "module {top} of crate {} has no layer: add it to tests/architecture.rs",
                krate.name
            ));
        }
    }
    for listed in layers.keys() {
        if !tops.contains(listed) {
            out.push(format!(
                "layer entry {listed} of crate {} names no module: remove it from tests/architecture.rs",
                krate.name
            ));
        }
    }
    out
}

/// The message for an import that runs against the layers, if it does (imports of the crate root are left to rule 1).
fn layer_violation(krate: &Crate, layers: &BTreeMap<&str, usize>, edge: &Edge) -> Option<String> {
    let (from, to) = (edge.from.first()?, edge.to.first()?);
    if from == to {
        return None;
    }
    let (lf, lt) = (layers.get(from.as_str())? + 1, layers.get(to.as_str())? + 1);
    let why = if lt > lf {
        format!("{from} (layer {lf}) imports {to} (layer {lt}), downstream on the light path")
    } else if lt == lf {
        format!("{from} and {to} share layer {lf} and must not import each other")
    } else {
        return None;
    };
    Some(format!("{}\n    {why}", cite(krate, edge)))
}

/// Rule 2: every import between top-level modules runs upstream along the layers.
#[test]
fn imports_follow_the_light_path() {
    let mut problems = Vec::new();
    for (krate, edges) in crates_with_edges() {
        let Some(layers) = layer_map(&krate.name) else {
            problems.push(format!(
                "crate {} has no layers: add it to LAYERS in tests/architecture.rs",
                krate.name
            ));
            continue;
        };
        problems.extend(layer_list_problems(&krate, &layers));
        problems.extend(
            edges
                .iter()
                .filter_map(|e| layer_violation(&krate, &layers, e)),
        );
    }
    assert!(problems.is_empty(), "\n{}\n", problems.join("\n"));
}

/// The dependency names of the `[dependencies]` sections of a Cargo.toml (target-specific ones included).
fn dependency_names(toml: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let mut in_deps = false;
    for (i, raw) in toml.lines().enumerate() {
        let line = raw.split('#').next().unwrap().trim();
        if line.starts_with('[') {
            let header = line.trim_matches(|c| c == '[' || c == ']').trim();
            let (table, key) = match header.rsplit_once('.') {
                Some((t, k)) if t == "dependencies" || t.ends_with(".dependencies") => (t, Some(k)),
                _ => (header, None),
            };
            in_deps =
                key.is_none() && (table == "dependencies" || table.ends_with(".dependencies"));
            if let Some(name) = key {
                out.push((i + 1, name.trim_matches('"').to_string()));
            }
            continue;
        }
        if !in_deps || line.is_empty() {
            continue;
        }
        let key = line
            .split(['=', '.'])
            .next()
            .unwrap()
            .trim()
            .trim_matches('"');
        out.push((i + 1, key.to_string()));
        if let Some(pkg) = line.split("package").nth(1) {
            let renamed = pkg.trim_start_matches([' ', '=']).trim_start_matches('"');
            out.push((i + 1, renamed.split('"').next().unwrap().to_string()));
        }
    }
    out
}

/// Rule 3: the core names none of the twin, io, report, plotting or codec crates.
#[test]
fn core_depends_on_no_simulator_plotting_or_codec_crate() {
    let path = root().join("crates/core/Cargo.toml");
    let text = fs::read_to_string(&path).expect("read crates/core/Cargo.toml");
    let deps = dependency_names(&text);
    assert!(
        !deps.is_empty(),
        "found no [dependencies] in crates/core/Cargo.toml"
    );
    let bad: Vec<String> = deps
        .iter()
        .filter(|(_, name)| FORBIDDEN_IN_CORE.contains(&name.replace('_', "-").as_str()))
        .map(|(line, name)| format!("crates/core/Cargo.toml:{line}: depends on {name}"))
        .collect();
    assert!(
        bad.is_empty(),
        "\nthe reconstruction core must not depend on the twin, io, report or a plotting/codec crate:\n{}\n",
        bad.join("\n")
    );
}

/// A crate made of the given module paths, with no source text (for the checker's own test).
fn synthetic_crate(modules: &[&str], uses: &[(&str, &str)]) -> Crate {
    let mut files = BTreeMap::new();
    for m in modules {
        let module: ModPath = m
            .split("::")
            .filter(|s| !s.is_empty())
            .map(String::from)
            .collect();
        let text: String = uses
            .iter()
            .filter(|(f, _)| f == m)
            .map(|(_, u)| format!("{u}\n"))
            .collect();
        let file = SourceFile {
            module: module.clone(),
            path: PathBuf::from(m),
            uses: use_statements(&text),
        };
        files.insert(module, file);
    }
    Crate {
        name: "synthetic".to_string(),
        files,
    }
}

/// The checker itself: groups, aliases, `super`, re-exports, test modules, Cargo.toml tables.
#[test]
fn the_checker_reads_groups_super_reexports_and_test_modules() {
    let paths: Vec<String> = expand_use("crate::a::{b, c::{D, E as F}, self}")
        .into_iter()
        .map(|(p, a)| {
            format!(
                "{}{}",
                p.join("::"),
                a.map(|a| format!(" as {a}")).unwrap_or_default()
            )
        })
        .collect();
    assert_eq!(
        paths,
        [
            "crate::a::b",
            "crate::a::c::D",
            "crate::a::c::E as F",
            "crate::a"
        ]
    );

    let text = "use crate::x::{\n    A, // a\n    B,\n};\nlet s = \"use more\";\npub use y::Z;\n#[cfg(test)]\nmod tests;\nuse super::W;\n#[cfg(test)]\nmod t {\n    use crate::late::Q;\n}\n";
    let stmts: Vec<(usize, bool, String)> = use_statements(text)
        .into_iter()
        .map(|u| {
            (
                u.line,
                u.is_pub,
                expand_use(&u.text)
                    .into_iter()
                    .map(|(p, _)| p.join("::"))
                    .collect::<Vec<_>>()
                    .join(" "),
            )
        })
        .collect();
    let expected = [
        (1, false, "crate::x::A crate::x::B"),
        (6, true, "y::Z"),
        (9, false, "super::W"),
    ];
    assert_eq!(stmts, expected.map(|(l, p, t)| (l, p, t.to_string())));

    let krate = synthetic_crate(
        &["", "cube", "a", "a::b", "a::c"],
        &[("", "pub use cube::Cube;"), ("a", "pub use c::Thing;")],
    );
    let m = |s: &str| -> ModPath {
        s.split("::")
            .filter(|s| !s.is_empty())
            .map(String::from)
            .collect()
    };
    let p = |s: &str| -> Vec<String> { s.split("::").map(String::from).collect() };
    assert_eq!(
        resolve(&krate, &m("a::b"), &p("crate::Cube")),
        Some(m("cube"))
    );
    assert_eq!(
        resolve(&krate, &m("a::b"), &p("super::c::X")),
        Some(m("a::c"))
    );
    assert_eq!(
        resolve(&krate, &m("a::b"), &p("super::Thing")),
        Some(m("a::c"))
    );
    assert_eq!(
        resolve(&krate, &m("a::b"), &p("super::Other")),
        Some(m("a"))
    );
    assert_eq!(resolve(&krate, &m("a::b"), &p("serde::Serialize")), None);

    let toml = "[package]\nname = \"x\"\n[dependencies]\nserde.workspace = true\nimage = \"0.25\"\n[dev-dependencies]\nexr = \"1\"\n[dependencies.plotters]\nversion = \"0.3\"\n";
    let names: Vec<String> = dependency_names(toml).into_iter().map(|(_, n)| n).collect();
    assert_eq!(names, ["serde", "image", "plotters"]);

    // Paths named in code: a child module's (a field `c::Thing` in `a`) is an edge like a `use`;
    // a type's (`Vec::new`), another crate's and a qualified path's (`<T as Tr>::f`) are not.
    let line = "    x: c::Thing, y: Vec::new(), z: std::mem::take(&mut w), f: <T as Tr>::f(),";
    assert_eq!(
        inline_paths(line),
        ["c::Thing", "Vec::new", "std::mem::take"]
    );
    let krate = synthetic_crate(
        &["", "a", "a::c"],
        &[("a", line), ("a::c", "use super::Y;")],
    );
    let found: Vec<(String, String, String)> = edges(&krate)
        .into_iter()
        .map(|e| (show(&e.from), show(&e.to), e.text))
        .collect();
    let expected = [
        ("a", "a::c", "`c::Thing` (named in code)"),
        ("a::c", "a", "use super::Y;"),
    ];
    let expected = expected.map(|(f, t, x)| (f.to_string(), t.to_string(), x.to_string()));
    assert_eq!(found.len(), 2, "{found:?}");
    assert!(expected.iter().all(|e| found.contains(e)), "{found:?}");
}
