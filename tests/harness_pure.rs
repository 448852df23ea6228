//! The benchmark harness's pure parts (`benches/harness/{stats,svg}.rs`, included by path:
//! a `harness = false` bench runs no tests of its own): the equal-error speed-up it reports
//! and the plots it writes. Its GPU parts run in CI as `cargo bench --bench harness --
//! all --quick` (docs/PERFORMANCE.md).

#[path = "../benches/harness/stats.rs"]
#[allow(dead_code)]
mod stats;
#[path = "../benches/harness/svg.rs"]
#[allow(dead_code)]
mod svg;

use stats::{Reach, cost_model, equal_error_speedups, pair_ratios, parse_image_size, summary, time_to_reach};

/// Float comparisons of closed-form values: only rounding separates them.
const EPS: f64 = 1e-9;

#[test]
fn test01_summary_median_quartiles_spread() {
    let s = summary(&[5.0, 1.0, 3.0, 2.0, 4.0, f64::NAN]);
    assert_eq!((s.n, s.min, s.max, s.median), (5, 1.0, 5.0, 3.0));
    assert_eq!((s.p25, s.p75), (2.0, 4.0));
    assert!((summary(&[1.0, 2.0]).median - 1.5).abs() < EPS);
    assert!(summary(&[]).median.is_nan());
}

#[test]
fn test02_time_to_reach_interpolates_in_log_log() {
    // Error falling as t^-1/2: 1 at t = 1, 0.5 at t = 4; 0.7071 is reached at t = 2.
    let curve = [(1.0, 1.0), (4.0, 0.5)];
    match time_to_reach(&curve, 0.5f64.sqrt()) {
        Some(Reach::At(t)) => assert!((t - 2.0).abs() < 1e-9, "{t}"),
        r => panic!("{r:?}"),
    }
    assert_eq!(time_to_reach(&curve, 2.0), Some(Reach::NoLaterThan(1.0)));
    assert_eq!(time_to_reach(&curve, 0.1), Some(Reach::LaterThan(4.0)));
    assert_eq!(time_to_reach(&[], 0.1), None);
}

#[test]
fn test03_time_to_reach_takes_the_first_crossing_of_a_noisy_curve() {
    let curve = [(1.0, 1.0), (2.0, 0.4), (3.0, 0.6), (4.0, 0.3)];
    match time_to_reach(&curve, 0.5) {
        Some(Reach::At(t)) => assert!(t > 1.0 && t < 2.0, "{t}"),
        r => panic!("{r:?}"),
    }
}

#[test]
fn test04_equal_error_speedup_of_parallel_curves() {
    // The slow method needs 10 times the time for every error: speed-up 10 everywhere it
    // is bracketed, a lower bound (with the t^-1/2 extrapolation) past its last point.
    let fast: Vec<(f64, f64)> = [1.0, 2.0, 4.0, 8.0].iter().map(|&t: &f64| (t, t.powf(-0.5))).collect();
    let slow: Vec<(f64, f64)> =
        [1.0, 5.0, 10.0, 20.0, 40.0].iter().map(|&t: &f64| (t, (t / 10.0).powf(-0.5))).collect();
    let s = equal_error_speedups(&fast, &slow);
    assert_eq!(s.len(), 4);
    for p in &s[..3] {
        assert!(matches!(p.slow, Reach::At(_)));
        assert!((p.speedup - 10.0).abs() < 1e-9, "{p:?}");
        assert_eq!(p.display(), "10.0x");
    }
    let last = s[3];
    assert_eq!(last.slow, Reach::LaterThan(40.0));
    assert!((last.speedup - 5.0).abs() < EPS);
    assert!((last.extrapolated.unwrap() - 10.0).abs() < 1e-9);
    assert_eq!(last.display(), ">= 5.0x (~10x)");
}

#[test]
fn test05_svg_plot_is_well_formed_and_drops_what_a_log_axis_cannot_show() {
    let plot = svg::Plot {
        title: "RMSE <against> time & more".into(),
        subtitle: "adapter".into(),
        x_label: "seconds".into(),
        y_label: "relative RMSE".into(),
        log_x: true,
        log_y: true,
        series: vec![
            svg::Series { label: "a".into(), points: vec![(0.1, 1.0), (1.0, 0.3), (10.0, 0.1)], dashed: false },
            svg::Series { label: "b".into(), points: vec![(0.0, 1.0), (1.0, f64::NAN), (2.0, 0.5)], dashed: true },
        ],
    };
    let text = svg::render(&plot);
    assert!(text.starts_with("<svg") && text.trim_end().ends_with("</svg>"));
    assert!(text.contains("RMSE &lt;against&gt; time &amp; more"));
    assert!(!text.contains("NaN") && !text.contains("inf"));
    assert_eq!(text.matches("<polyline").count(), 1, "b keeps one point: no line");
    assert_eq!(text.matches("<circle").count(), 4);
    // Every tag opened is closed: a cheap check that the document parses.
    assert_eq!(text.matches("<svg").count(), text.matches("</svg>").count());
    assert_eq!(text.matches("<text").count(), text.matches("</text>").count());
}

#[test]
fn test06_svg_linear_axes_and_number_labels() {
    assert_eq!(svg::format_number(0.5), "0.5");
    assert_eq!(svg::format_number(20.0), "20");
    assert_eq!(svg::format_number(1e6), "1e6");
    let plot = svg::Plot {
        title: "t".into(),
        subtitle: String::new(),
        x_label: "patches".into(),
        y_label: "ms".into(),
        log_x: false,
        log_y: false,
        series: vec![svg::Series {
            label: "step".into(),
            points: vec![(6292.0, 80.0), (71572.0, 300.0)],
            dashed: false,
        }],
    };
    let text = svg::render(&plot);
    assert!(text.contains(">0<"), "linear axes of positive data start at 0");
    assert_eq!(text.matches("<polyline").count(), 1);
}

#[test]
fn test07_image_sizes_parse_and_bad_ones_say_how_to_write_them() {
    assert_eq!(parse_image_size("7680x4320"), Ok((7680, 4320)));
    assert_eq!(parse_image_size(" 512X288 "), Ok((512, 288)));
    for bad in ["512", "0x512", "512x", "x", "512x-1", "a x b"] {
        let e = parse_image_size(bad).unwrap_err();
        assert!(e.contains(bad) && e.contains("WIDTHxHEIGHT"), "{bad}: {e}");
    }
}

#[test]
fn test08_cost_model_recovers_start_time_noise_and_floor() {
    // Runs made exactly by the model: start 0.5 s, 20 ms a sample, noise 0.6, floor 1 %.
    let made = |start: f64, per: f64, noise: f64, floor: f64, budgets: &[f64]| -> Vec<(f64, f64, f64)> {
        budgets.iter().map(|&n| (n, start + n * per, (noise * noise / n + floor * floor).sqrt())).collect()
    };
    let budgets = [1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0];
    let m = cost_model(&made(0.5, 0.02, 0.6, 0.01, &budgets)).expect("a fit");
    assert!((m.start - 0.5).abs() < 1e-9 && (m.per_sample - 0.02).abs() < 1e-12, "{m:?}");
    assert!((m.noise - 0.6).abs() < 1e-9 && (m.floor - 0.01).abs() < 1e-9, "{m:?}");
    // Only the budgets of at least a fiftieth of the largest (20 and up) are fitted.
    assert_eq!(m.runs, 6);
    assert!((m.noise_time() - 0.36 * 20.0).abs() < 1e-6);
    // A transient below a fiftieth of the largest budget does not enter the fit.
    let mut early = made(0.5, 0.02, 0.6, 0.0, &budgets);
    early[0].2 = 5.0;
    let m = cost_model(&early).expect("a fit");
    assert!((m.noise - 0.6).abs() < 1e-9 && m.floor.abs() < 1e-9, "{m:?}");
}

#[test]
fn test09_cost_model_clamps_a_negative_floor_and_refuses_too_few_runs() {
    // Error falling faster than 1 / sqrt(N) (a transient): the best floor^2 is negative, so
    // the fit takes no floor and the noise alone.
    let runs: Vec<(f64, f64, f64)> = [100.0, 200.0, 400.0].iter().map(|&n| (n, n * 0.01, 1.0 / n)).collect();
    let m = cost_model(&runs).expect("a fit");
    assert_eq!(m.floor, 0.0);
    assert!(m.noise > 0.0 && m.noise.is_finite());
    // Two runs are too few; a time that falls with the budget has no time a sample.
    assert_eq!(cost_model(&runs[..2]), None);
    let flat: Vec<(f64, f64, f64)> =
        [100.0f64, 200.0, 400.0].iter().map(|&n| (n, 3.0 - 0.001 * n, 0.1 / n.sqrt())).collect();
    assert_eq!(cost_model(&flat), None);
}

#[test]
fn test10_the_gpu_scripts_parse() {
    // tools/gpu/ runs only where a GPU is lent (docs/PERFORMANCE.md, "On a GPU"); CI has
    // none, so at least a syntax error must not wait for that day. `bash -n` parses without
    // running.
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    for script in ["tools/gpu/prepare.sh", "tools/gpu/run.sh", "tools/gpu/tests.sh"] {
        let out = std::process::Command::new("bash").arg("-n").arg(root.join(script)).output().expect("bash runs");
        assert!(out.status.success(), "{script}: {}", String::from_utf8_lossy(&out.stderr));
    }
}

#[test]
fn test11_pair_ratios_pair_each_run_with_its_own() {
    // The views study: all cameras' time over one camera's, pair by pair (not median over
    // median), and a pair missing its second run left out.
    assert_eq!(pair_ratios(&[10.0, 12.0, 11.0], &[15.0, 15.0, 22.0]), vec![1.5, 1.25, 2.0]);
    assert_eq!(pair_ratios(&[10.0, 20.0], &[30.0]), vec![3.0]);
    assert!(pair_ratios(&[], &[1.0]).is_empty());
}
