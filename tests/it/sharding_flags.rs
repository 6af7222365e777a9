//! The examples' `--shard I/N --out FILE` / `--merge FILE...` flags (`sharding`): parsing, and
//! shard files through a session on a tiny Monte Carlo (one slot, 40 runs: milliseconds), and
//! through a hand-looped example's per-run records (`Session::records`), and through the
//! examples whose sums over runs are exact (`Session::sums`: boje_rate, lv2_fusion,
//! boje_circle, each on a few short runs).

use std::path::PathBuf;

use crate::exact_sum::{ExactSum, ExactSums};
use crate::sharding::{Args, Mode, Session, parse};
use estim::filters::ValidationError;
use estim::filters::monte_carlo::{MonteCarlo, Recorder};
use estim::nalgebra::{Matrix1, Vector1};

fn err(args: &[&str]) -> String {
    parse(args.iter().copied()).unwrap_err().to_string()
}

#[test]
fn flags_parse_and_bad_ones_are_refused_with_a_reason() {
    let shard = parse(["--quick", "--shard", "2/4", "--out", "s2.json", "--json"]).unwrap();
    assert_eq!(
        shard.mode,
        Mode::Shard {
            index: 2,
            count: 4,
            out: PathBuf::from("s2.json")
        }
    );
    let merge = parse([
        "--merge", "a.json", "b.json", "--quick", "--stats", "m.json",
    ])
    .unwrap();
    assert_eq!(
        merge,
        Args {
            mode: Mode::Merge {
                files: vec![PathBuf::from("a.json"), PathBuf::from("b.json")]
            },
            stats: Some(PathBuf::from("m.json")),
        }
    );
    assert_eq!(parse(["--quick"]).unwrap().mode, Mode::Whole);

    for (args, reason) in [
        (&["--shard", "4/4", "--out", "f"][..], "below N = 4"),
        (&["--shard", "0/0", "--out", "f"], "N >= 1"),
        (&["--shard", "1-4", "--out", "f"], "takes I/N"),
        (&["--shard", "-1/4", "--out", "f"], "takes I/N"),
        (&["--shard", "--out", "f"], "needs a value"),
        (&["--shard", "x/4", "--out", "f"], "takes I/N"),
        (&["--shard", "1/4"], "--shard needs --out"),
        (&["--out", "f"], "--out goes with --shard"),
        (&["--merge"], "--merge needs the shard files"),
        (&["--merge", "--quick"], "--merge needs the shard files"),
        (
            &["--shard", "0/2", "--out", "f", "--merge", "a"],
            "cannot be combined",
        ),
        (
            &["--shard", "0/2", "--out", "f", "--stats", "s"],
            "not a shard",
        ),
        (
            &["--shard", "0/2", "--shard", "1/2", "--out", "f"],
            "given twice",
        ),
    ] {
        let message = err(args);
        assert!(message.contains(reason), "{args:?}: {message}");
        assert!(message.contains("usage"), "{args:?}: {message}");
    }
}

/// A file name of its own under the temporary folder.
fn temp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("estim-sharding-{}-{name}", std::process::id()))
}

/// The statistics (their `Debug`, which prints every f64 exactly) and the runs of each shard.
type Merged = (String, Vec<Vec<usize>>);

/// A tiny experiment: 40 runs of a 1-state "filter" at one slot, each run's estimate a
/// function of its seed; per shard, the list of its runs (what `Session::extra` carries).
fn experiment(session: &Session, runs: usize) -> Result<Option<Merged>, String> {
    let mc = MonteCarlo::new(runs, 1).unwrap().with_seed(5);
    let seen = std::sync::Mutex::new(Vec::new());
    let simulate = |run: usize, seed: u64, rec: &mut Recorder| -> Result<(), ValidationError> {
        seen.lock().unwrap().push(run);
        let x = Vector1::new((seed % 1000) as f64 / 1000.0 - 0.5);
        rec.record_estimate(0, &x, &(x * 0.5), &Matrix1::new(1.0 / 48.0))
    };
    let stats = session
        .run("tiny", &mc, simulate)
        .map_err(|e| e.to_string())?;
    let mut mine = seen.into_inner().unwrap();
    mine.sort();
    let extra = session.extra("tiny", mine).map_err(|e| e.to_string())?;
    Ok(stats.zip(extra).map(|(s, e)| (format!("{s:?}"), e)))
}

fn session(args: &[&str], settings: &str) -> Result<Session, String> {
    let args = parse(args.iter().copied()).map_err(|e| e.to_string())?;
    Session::new("tiny", settings, args).map_err(|e| e.to_string())
}

#[test]
fn shards_written_and_merged_equal_the_whole_run_and_bad_files_are_refused() {
    let files: Vec<PathBuf> = (0..3).map(|i| temp(&format!("s{i}.json"))).collect();
    let names: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
    let (whole_stats, merged_stats) = (temp("whole-stats.json"), temp("merged-stats.json"));

    let whole = session(&["--stats", &whole_stats.display().to_string()], "--quick").unwrap();
    let (expected, all_runs) = experiment(&whole, 40).unwrap().unwrap();
    whole.finish().unwrap();
    assert_eq!(all_runs, [(0..40).collect::<Vec<_>>()]);

    for (i, name) in names.iter().enumerate() {
        let s = session(&["--shard", &format!("{i}/3"), "--out", name], "--quick").unwrap();
        assert_eq!(experiment(&s, 40).unwrap(), None);
        s.finish().unwrap();
    }
    // In any order: the merge sorts them by shard index.
    let merge_args = [
        "--merge",
        &names[2],
        &names[0],
        &names[1],
        "--stats",
        &merged_stats.display().to_string(),
    ];
    let merge = session(&merge_args, "--quick").unwrap();
    let (merged, per_shard) = experiment(&merge, 40).unwrap().unwrap();
    merge.finish().unwrap();
    // Bit for bit: the statistics' Debug prints every f64 exactly (shortest round-trip form),
    // and the --stats files are the same bytes.
    assert_eq!(merged, expected);
    assert_eq!(
        std::fs::read(&merged_stats).unwrap(),
        std::fs::read(&whole_stats).unwrap()
    );
    assert_eq!(per_shard.concat(), all_runs[0]);
    assert_eq!(per_shard.len(), 3);

    // What the merge refuses, with the reason.
    let refused = |args: &[&str], settings: &str| match session(args, settings) {
        Err(e) => e,
        Ok(s) => experiment(&s, 40).unwrap_err(),
    };
    let missing = refused(&["--merge", &names[0], &names[2]], "--quick");
    assert!(missing.contains("shards 1 of 3 are missing"), "{missing}");
    let twice = refused(&["--merge", &names[0], &names[1], &names[1]], "--quick");
    assert!(twice.contains("given twice"), "{twice}");
    let flags = refused(&["--merge", &names[0], &names[1], &names[2]], "full");
    assert!(flags.contains("settings '--quick'"), "{flags}");
    // The same files, merged into an experiment of 41 runs.
    let merge = session(&["--merge", &names[0], &names[1], &names[2]], "--quick").unwrap();
    let size = experiment(&merge, 41).unwrap_err();
    assert!(size.contains("not this run's"), "{size}");
    let absent = temp("absent.json");
    let gone = refused(&["--merge", &absent.display().to_string()], "--quick");
    assert!(gone.contains("cannot read"), "{gone}");
    let corrupt = temp("corrupt.json");
    let text = std::fs::read_to_string(&files[1]).unwrap();
    std::fs::write(&corrupt, &text[..text.len() / 2]).unwrap();
    let broken = refused(
        &[
            "--merge",
            &names[0],
            &corrupt.display().to_string(),
            &names[2],
        ],
        "--quick",
    );
    assert!(
        broken.contains("is not a shard file or is corrupt"),
        "{broken}"
    );
    let other = temp("other.json");
    std::fs::write(
        &other,
        text.replace("\"example\":\"tiny\"", "\"example\":\"lu_delays\""),
    )
    .unwrap();
    let foreign = refused(&["--merge", &other.display().to_string()], "--quick");
    assert!(
        foreign.contains("shards of lu_delays, not of tiny"),
        "{foreign}"
    );

    for f in files
        .iter()
        .chain([&whole_stats, &merged_stats, &corrupt, &other])
    {
        let _ = std::fs::remove_file(f);
    }
}

/// The shard files and `--stats` of a hand-looped example (`Session::records`): the example's
/// session of `args` over `runs` runs (7 runs of 150 steps: tens of milliseconds).
fn manoeuvring(args: &[&str], runs: usize) -> Result<Option<String>, String> {
    let args = parse(args.iter().copied()).map_err(|e| e.to_string())?;
    let s = Session::new("manoeuvring_target", "--quick", args).map_err(|e| e.to_string())?;
    let summary =
        crate::manoeuvring_target::monte_carlo_in(runs, 0x1aa5, &s).map_err(|e| e.to_string())?;
    s.finish().map_err(|e| e.to_string())?;
    Ok(summary.map(|s| format!("{s:?}")))
}

#[test]
fn a_hand_looped_example_merges_to_its_whole_run_bit_for_bit() {
    let files: Vec<PathBuf> = (0..3).map(|i| temp(&format!("mt{i}.json"))).collect();
    let names: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
    let (whole_stats, merged_stats) = (temp("mt-whole.json"), temp("mt-merged.json"));
    let whole = manoeuvring(&["--stats", &whole_stats.display().to_string()], 7)
        .unwrap()
        .unwrap();
    // 7 runs in 3 shards: runs 0-1, 2-3, 4-6 (uneven, as `shard_runs` splits them).
    for (i, name) in names.iter().enumerate() {
        let shard = manoeuvring(&["--shard", &format!("{i}/3"), "--out", name], 7).unwrap();
        assert_eq!(shard, None);
    }
    let stats = merged_stats.display().to_string();
    let merged = manoeuvring(
        &[
            "--merge", &names[1], &names[2], &names[0], "--stats", &stats,
        ],
        7,
    )
    .unwrap()
    .unwrap();
    // Bit for bit: the summary's Debug prints every f64 exactly, and the --stats files (the
    // bits of every sum over runs) are the same bytes.
    assert_eq!(merged, whole);
    assert_eq!(
        std::fs::read(&merged_stats).unwrap(),
        std::fs::read(&whole_stats).unwrap()
    );
    // The same files merged into a Monte Carlo of another size are refused, with the reason.
    let size = manoeuvring(&["--merge", &names[0], &names[1], &names[2]], 8).unwrap_err();
    assert!(size.contains("holds runs 0..2 of 7"), "{size}");
    for f in files.iter().chain([&whole_stats, &merged_stats]) {
        let _ = std::fs::remove_file(f);
    }
}

#[test]
fn an_example_without_shards_refuses_the_flags_instead_of_running_whole() {
    use crate::sharding::refuse;
    assert!(
        refuse(
            "large_state",
            "no Monte Carlo",
            parse(["--quick", "--json"]).unwrap()
        )
        .is_ok()
    );
    for args in [
        &["--shard", "0/2", "--out", "f"][..],
        &["--merge", "a", "b"],
        &["--stats", "s"],
    ] {
        let message = refuse(
            "large_state",
            "no Monte Carlo",
            parse(args.iter().copied()).unwrap(),
        )
        .unwrap_err()
        .to_string();
        assert!(
            message.contains("large_state does not take --shard/--merge/--stats: no Monte Carlo"),
            "{args:?}: {message}"
        );
    }
}

/// The exact sum is correctly rounded whatever the order: Python's `math.fsum` test values
/// (ties to even across partials, cancellation; the last is Σ 1/n, n ≤ 1000, to the last bit),
/// each summed forwards, backwards and split in two merged halves.
#[test]
fn exact_sums_are_correctly_rounded_in_any_order() {
    let p = |e: i32| 2f64.powi(e);
    let harmonic: Vec<f64> = (1..=1000).map(|n| 1.0 / n as f64).collect();
    let cases: [(Vec<f64>, f64); 7] = [
        (vec![p(53), -0.5, -p(-54)], p(53) - 1.0),
        (vec![p(53), 1.0, p(-100)], p(53) + 2.0),
        (vec![p(53) + 10.0, 1.0, p(-100)], p(53) + 12.0),
        (vec![p(53) - 4.0, 0.5, p(-54)], p(53) - 3.0),
        (vec![1e100, 1.0, -1e100, 1e-100, 1e50, -1.0, -1e50], 1e-100),
        (vec![0.1; 10], 1.0),
        (harmonic, f64::from_bits(0x401D_F11F_45F4_E61A)),
    ];
    for (terms, want) in cases {
        let sum = |xs: &mut dyn Iterator<Item = &f64>| {
            let mut s = ExactSum::default();
            xs.for_each(|x| s.add(*x));
            s
        };
        let (a, b) = terms.split_at(terms.len() / 2);
        let mut split = sum(&mut b.iter());
        split.merge(&sum(&mut a.iter().rev()));
        for s in [sum(&mut terms.iter()), sum(&mut terms.iter().rev()), split] {
            assert_eq!(s.value().to_bits(), want.to_bits(), "{terms:?}");
        }
    }
    // Random terms of mixed sizes and signs on the grid 2⁻⁹⁰ (k·2^(e−90), k < 2⁵³, e < 40): the
    // exact sum in i128 fixed point, rounded once (int → float casts round to nearest even),
    // is the reference; every order and split must give its bits.
    use rand::{Rng, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(39);
    for _ in 0..50 {
        let ks: Vec<i128> = (0..300)
            .map(|_| {
                let k = rng.random_range(-(1i128 << 53)..1i128 << 53);
                k << rng.random_range(0..40)
            })
            .collect();
        let terms: Vec<f64> = ks.iter().map(|k| *k as f64 * p(-90)).collect();
        let want = ks.iter().sum::<i128>() as f64 * p(-90);
        let mut forward = ExactSum::default();
        terms.iter().for_each(|x| forward.add(*x));
        let (mut back, mut odd) = (ExactSum::default(), ExactSum::default());
        for (i, x) in terms.iter().enumerate().rev() {
            if i % 2 == 0 {
                back.add(*x)
            } else {
                odd.add(*x)
            }
        }
        back.merge(&odd);
        assert_eq!(forward.value().to_bits(), want.to_bits());
        assert_eq!(back.value().to_bits(), want.to_bits());
    }
    // Non-finite terms are summed apart, as IEEE does.
    let mut s = ExactSums::new(2);
    for (i, x) in [(0, 1.0), (0, f64::INFINITY), (1, f64::INFINITY), (1, -1.0)] {
        s.add(i, x);
    }
    assert_eq!(s.values(), [f64::INFINITY, f64::INFINITY]);
    s.add(1, f64::NEG_INFINITY);
    assert!(s.value(1).is_nan());
}

/// `body` (an example body's results through a session: their `Debug`, every f64 exact) whole and as the merge of 3 shards (files given in shuffled order): the results and
/// the `--stats` bytes must be equal, bit for bit.
fn shards_merge_to_the_whole_run(
    name: &str,
    body: impl Fn(&Session) -> Result<Option<String>, Box<dyn std::error::Error>>,
) {
    let run = |args: &[&str]| -> Option<String> {
        let args = parse(args.iter().copied()).unwrap();
        let s = Session::new(name, "--quick", args).unwrap();
        let out = body(&s).unwrap();
        s.finish().unwrap();
        out
    };
    let files: Vec<String> = (0..3)
        .map(|i| temp(&format!("{name}{i}.json")).display().to_string())
        .collect();
    let (whole_stats, merged_stats) = (temp(&format!("{name}-w")), temp(&format!("{name}-m")));
    let whole = run(&["--stats", &whole_stats.display().to_string()]).unwrap();
    for (i, f) in files.iter().enumerate() {
        assert_eq!(run(&["--shard", &format!("{i}/3"), "--out", f]), None);
    }
    let stats = merged_stats.display().to_string();
    let merged = run(&[
        "--merge", &files[2], &files[0], &files[1], "--stats", &stats,
    ])
    .unwrap();
    assert_eq!(merged, whole, "{name}");
    assert_eq!(
        std::fs::read(&merged_stats).unwrap(),
        std::fs::read(&whole_stats).unwrap(),
        "{name}"
    );
    for f in files
        .iter()
        .map(PathBuf::from)
        .chain([whole_stats, merged_stats])
    {
        let _ = std::fs::remove_file(f);
    }
}

/// boje_rate, lv2_fusion and boje_circle, each on a few short runs (tens of milliseconds):
/// their shards merge to the whole run bit for bit.
#[test]
fn examples_with_exact_sums_merge_to_their_whole_run_bit_for_bit() {
    use crate::boje_circle::{circle_monte_carlo_in, circle_smoothing_in};
    use crate::boje_rate::{RateConfig, rate_experiment_in};
    use crate::lv2_fusion::{Lv2Config, monte_carlo_in};
    use estim::models::boje::CircleConfig;

    let rate = RateConfig {
        runs: 5,
        steps: 1_100,
        ..RateConfig::paper()
    };
    shards_merge_to_the_whole_run("boje_rate", |s| {
        let r = rate_experiment_in(&rate, s)?;
        if let Some(r) = &r {
            s.summary("runs", &r.rms_over_time_deg_s);
        }
        Ok(r.map(|r| format!("{r:?}")))
    });
    let mut lv2 = Lv2Config::quick();
    lv2.monte_carlo.runs = 4_500;
    shards_merge_to_the_whole_run("lv2_fusion", |s| {
        let mc = monte_carlo_in(&lv2.sigmas, &lv2.monte_carlo, lv2.false_alarm, s)?;
        if let Some(mc) = &mc {
            s.summary("readings", &[mc.chi2_mean, mc.chi2_variance]);
        }
        Ok(mc.map(|m| format!("{m:?}")))
    });
    let circle = CircleConfig {
        runs: 4,
        t_end: 3.0,
        ..CircleConfig::paper()
    };
    shards_merge_to_the_whole_run("boje_circle", |s| {
        let mc = circle_monte_carlo_in(&circle, "main", true, s)?;
        let smoothed = circle_smoothing_in(&circle, s)?;
        Ok(mc.zip(smoothed).map(|(m, mut sm)| {
            sm.wall_s = 0.0;
            format!("{m:?} {sm:?}")
        }))
    });
}
