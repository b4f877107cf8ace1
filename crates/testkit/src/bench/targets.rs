//! What the bench targets under `benches/` share: a `main` that runs the measurements named
//! on the command line, and the frame size they take from the environment.
//!
//! `cargo bench --bench ingp -- render_1080p_final` runs that measurement of `benches/ingp.rs`
//! (a name no measurement has picks every one whose name contains it: `-- render`); without a
//! name it runs them all, and `--list` lists them. Built by `cargo test --all-targets` (no `--bench` on the command line), a
//! target only lists its measurements: they take minutes and print figures, they do not test.

/// One measurement of a bench target: its name, what it prints, and the function.
pub struct Measurement {
    /// The name `cargo bench --bench TARGET -- NAME` selects it by (a substring matches).
    pub name: &'static str,
    /// One line on what it measures.
    pub what: &'static str,
    /// The environment variable it needs, if any: run without it only when named.
    pub needs: Option<&'static str>,
    /// The measurement; it prints its figures and panics where an assertion of it fails.
    pub run: fn(),
}

impl Measurement {
    /// A measurement that needs nothing from the environment.
    pub const fn new(name: &'static str, what: &'static str, run: fn()) -> Self {
        Self {
            name,
            what,
            needs: None,
            run,
        }
    }

    /// A measurement that needs the environment variable `var` (a folder of data too large to
    /// keep in the repository): a run of every measurement skips it, saying so, when `var` is
    /// not set; named, it runs and fails without it.
    pub const fn needing(self, var: &'static str) -> Self {
        Self {
            needs: Some(var),
            ..self
        }
    }
}

/// Runs the measurements the command line names (all without a name), one after the other,
/// each under a heading. `target` is the bench target's name, for the listing.
pub fn main(target: &str, measurements: &[Measurement]) {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let benching = args.iter().any(|a| a == "--bench");
    let names: Vec<&str> = args
        .iter()
        .map(String::as_str)
        .filter(|a| !a.starts_with("--"))
        .collect();
    if !benching || args.iter().any(|a| a == "--list") {
        println!("cargo bench --bench {target} -- [NAME…] runs these (all without a name):");
        for m in measurements {
            let needs = m.needs.map_or(String::new(), |v| format!(" (needs {v})"));
            println!("  {}: {}{needs}", m.name, m.what);
        }
        return;
    }
    // A name picks the measurement of that name, or failing one, every name containing it.
    let picks = |m: &Measurement, n: &str| {
        let exact = measurements.iter().any(|k| k.name == n);
        if exact {
            m.name == n
        } else {
            m.name.contains(n)
        }
    };
    let chosen: Vec<&Measurement> = measurements
        .iter()
        .filter(|m| names.is_empty() || names.iter().any(|n| picks(m, n)))
        .collect();
    if chosen.is_empty() {
        eprintln!(
            "no measurement of {target} is named {}; `cargo bench --bench {target} -- --list` \
             lists them",
            names.join(" or ")
        );
        std::process::exit(2);
    }
    for m in chosen {
        if let Some(var) = m
            .needs
            .filter(|v| names.is_empty() && std::env::var_os(v).is_none())
        {
            println!("== {target} {}: skipped, {var} is not set", m.name);
            continue;
        }
        println!("== {target} {}: {}", m.name, m.what);
        (m.run)();
    }
}

/// The benchmarks' frame size: `NERFX_BENCH_SIZE=WxH`, or `default`.
pub fn bench_size(default: (u32, u32)) -> (u32, u32) {
    std::env::var("NERFX_BENCH_SIZE")
        .ok()
        .and_then(|s| {
            let (w, h) = s.split_once('x')?;
            Some((w.parse().ok()?, h.parse().ok()?))
        })
        .unwrap_or(default)
}
