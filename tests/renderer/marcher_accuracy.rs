//! The marcher against the exact reference (STYLE point 9): seeded random analytic scenes
//! and the demo scene at every quality preset, packed against per-ray layouts (tiles of any
//! size, sub-windows), the ray with no samples, requested outputs, the naive baseline, and
//! joint rendering against compositing separately rendered instances.
//!
//! Every comparison goes through `common::assert_close`, which names the worst pixel.

use crate::common;

use std::sync::Arc;

use common::*;
use glam::{DMat4, DVec3, Vec3};
use nerfx_core::camera::Camera;
use nerfx_core::field::{Aabb, Analytic, Capabilities, Field, Shape};
use nerfx_core::image::{Plane, Planes, Window};
use nerfx_core::render::{
    render, render_naive, render_with_progress, MarchParams, Outputs, Quality, RenderSettings,
    RenderStats,
};
use nerfx_core::scene::{FieldHandle, Instance, Scene};
use nerfx_testkit::bench::scenes::{build, SceneKind};
use nerfx_testkit::bench::suite::{fine_params, QUADRATURE_TOLERANCE};

const W: u32 = 64;
const H: u32 = 48;
const SEEDS: u64 = 12;

/// Preview: step = feature size / 2 (growing with distance by the cone to at most 2×),
/// edges bisected while `|Δσ|·δ·T > 5e-3` (at most 6 times), stop at T < 1e-3: each of
/// those is 5–10× Final's, and a 6-level bracket of a dense edge may stay wider than the
/// tolerance. Bounds: alpha and RGB 1e-2, PSNR 60 dB, depth 2e-3 (measured: see the test
/// output on failure).
const PREVIEW: Tol = Tol {
    min_psnr: 60.0,
    min_alpha_psnr: 55.0,
    rgb: 1e-2,
    alpha: 1e-2,
    depth_rel: 5e-3,
};

/// Draft: step = feature size (up to 4× with the cone), 2 bisections, stop at T < 1e-2,
/// so alpha is short by up to 1e-2 on every opaque pixel, and a silhouette thinner than a
/// step (a ray grazing a dense sphere) can be missed entirely: the per-pixel worst case is
/// bounded only by 1 − e^{−k·δ} (close to 1 for k = 200), so Draft's per-pixel bounds are that
/// loose and the image-wide PSNRs carry the test. Depth: the median is where the
/// accumulation crosses half of it, so an alpha error Δα moves it by `Δα/(σT)` — in a
/// half-transparent medium (σT ≈ 0.5 per unit) Δα ≈ 1e-2 moves it by 0.02 units at depths
/// ≥ 4, more where the crossing is slow; bound 1e-1.
const DRAFT: Tol = Tol {
    min_psnr: 45.0,
    min_alpha_psnr: 40.0,
    rgb: 1.0,
    alpha: 1.0,
    depth_rel: 1e-1,
};

/// Every seeded random scene at `quality` against the reference.
fn random_scenes_match_the_reference(quality: Quality, tol: Tol) {
    for seed in 0..SEEDS {
        let mut rng = SplitMix64::new(seed);
        let scene = random_scene(&mut rng);
        let camera = random_camera(&mut rng, W, H);
        let want = reference_full(&scene, &camera);
        let got = render_full(&scene, &camera, marched(quality.params()));
        let what = format!("{quality:?}, random scene {seed}");
        assert_sane(&what, &got);
        assert_close(&what, &got, &want, tol);
    }
}

#[test]
fn final_matches_the_reference_on_random_scenes() {
    random_scenes_match_the_reference(Quality::Final, FINAL);
}

#[test]
fn preview_matches_the_reference_on_random_scenes() {
    random_scenes_match_the_reference(Quality::Preview, PREVIEW);
}

#[test]
fn draft_matches_the_reference_on_random_scenes() {
    random_scenes_match_the_reference(Quality::Draft, DRAFT);
}

/// Regression: pixels (8, 26) and (9, 37) clip a pillar's corner inside the haze (see
/// [`a_dense_sheet_inside_fog_is_not_missed`]).
#[test]
fn demo_scene_final_matches_the_reference() {
    let (scene, camera) = nerfx_core::demo::scene_and_camera(96, 54).expect("demo scene");
    let want = reference_full(&scene, &camera);
    let got = render_full(&scene, &camera, marched(Quality::Final.params()));
    assert_sane("demo, Final", &got);
    assert_close("demo, Final", &got, &want, FINAL);
}

/// An analytic field that does not give its spans, as a trained field does not: the marcher
/// finds its edges by bisection and its thin sheets by density bounds.
struct Searched(Analytic);

impl Field for Searched {
    fn bounds(&self) -> Aabb {
        self.0.bounds()
    }
    fn density(&self, points: &[Vec3], sigma: &mut [f32]) {
        self.0.density(points, sigma)
    }
    fn radiance(&self, points: &[Vec3], dirs: &[Vec3], rgb: &mut [Vec3]) {
        self.0.radiance(points, dirs, rgb)
    }
    fn feature_size(&self) -> f32 {
        self.0.feature_size()
    }
    /// Density bounds, and no spans: the marcher searches the field's edges.
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            density_bounds: true,
            ..Capabilities::default()
        }
    }
    fn density_bounds(&self, regions: &[Aabb], bounds: &mut [f32]) {
        self.0.density_bounds(regions, bounds)
    }
    fn may_be_occupied(&self, region: &Aabb) -> bool {
        self.0.may_be_occupied(region)
    }
}

/// The same scene with every instance's field hidden behind [`Searched`].
fn searched(scene: &Scene) -> Scene {
    let instances: Vec<Instance> = scene
        .marched()
        .map(|inst| {
            let analytic = inst.handle().as_analytic().expect("an analytic scene");
            let field = FieldHandle::new(Arc::new(Searched(analytic.clone())));
            Instance::new(
                inst.name.clone(),
                field,
                inst.world_from_field(),
                inst.crop().copied(),
            )
            .expect("the same placement")
        })
        .collect();
    Scene::new(instances)
}

/// Fields without spans (trained fields) keep the marcher's edge search: the same random
/// scenes with their spans hidden still match the exact reference at Final.
#[test]
fn final_without_spans_matches_the_reference_on_random_scenes() {
    for seed in 0..SEEDS / 2 {
        let mut rng = SplitMix64::new(seed);
        let scene = random_scene(&mut rng);
        let camera = random_camera(&mut rng, W, H);
        let want = reference_full(&scene, &camera);
        let got = render_full(&searched(&scene), &camera, marched(Quality::Final.params()));
        let what = format!("Final without spans, random scene {seed}");
        assert_sane(&what, &got);
        assert_close(&what, &got, &want, FINAL);
    }
}

/// Every preset keeps its error target — the largest alpha and premultiplied colour error of
/// any pixel at most [`MarchParams::error_target`] — on the benchmark's demo and on its
/// sheets 1e-3 to 1e-5 units thick in haze, far thinner than any step: spans give their
/// faces exactly, where sampling finds them only if a bisection lands inside.
#[test]
fn every_preset_keeps_its_error_target_on_the_demo_and_thin_sheets() {
    let dir = std::env::temp_dir();
    for kind in [SceneKind::Demo, SceneKind::Sheets] {
        let bench = build(kind, 96, 54, &dir, None).expect("an analytic bench scene");
        let want = reference_full(&bench.scene, &bench.camera);
        for quality in Quality::ALL {
            let params = marched(quality.params());
            let got = render_full(&bench.scene, &bench.camera, params);
            let what = format!("{}, {quality:?}", kind.name());
            assert_sane(&what, &got);
            assert_close(&what, &got, &want, within_target(params));
        }
    }
}

/// The bench's dense blob (an instant-ngp snapshot whose rays stop inside) at Draft, in the
/// 16×16 window around the pixel where a mask segment one step long (its ends' density
/// ~240) holds a bump of nearly twice that: within Draft's error target (alpha and every
/// premultiplied colour channel) against the bench's fine march (not exact; its own error is
/// far below the target). Judged by its ends' jump alone, that step was not bisected and
/// the pixel's colour was off by 5.6e-2.
#[test]
fn draft_keeps_its_target_where_a_dense_mask_segment_is_one_step_long() {
    let dir = tempfile::tempdir().unwrap();
    let bench = build(SceneKind::Blob, 480, 270, dir.path(), None).expect("the blob");
    let window = Window::new(324, 160, 340, 176);
    let march = |params| {
        let settings = RenderSettings::new(params, Outputs::all());
        render(&bench.scene, &bench.camera, window, &settings).expect("a render")
    };
    let want = march(marched(fine_params()));
    let params = marched(Quality::Draft.params());
    let got = march(params);
    assert_sane("blob, Draft", &got);
    assert_close("blob, Draft", &got, &want, within_target(params));
}

/// The bench's dense blob at 1920×1080, Draft, in the 16×16 window around a pixel whose ray
/// meets a thin shell (density ~400, a few hundredths of a unit thick) between two nodes
/// of density ~9 one Draft step apart: within Draft's error target against the quadrature
/// reference. Judged by its ends and their flat curvature, that step was not bisected, the
/// shell went unseen and the pixel's colour was off by 0.12.
#[test]
fn draft_keeps_its_target_where_a_thin_shell_lies_between_two_nodes() {
    assert_blob_window_within_target(Window::new(994, 320, 1010, 336), Quality::Draft);
}

/// Preview on the blob at 1080p where rays enter it opaque: density ~7e4 right at its
/// mask's face, so a pixel's light comes from the first ~1e-5 units of the run. Its first
/// node must be probed at the face (and the full inset inside only where that rounds out of
/// the mask): probed the inset (~1.7e-5) inside, past the shell, pixel (711, 312)'s blue
/// was off by 1.7e-2 against the quadrature reference.
#[test]
fn preview_keeps_its_target_where_an_opaque_shell_is_thinner_than_the_inset() {
    assert_blob_window_within_target(Window::new(703, 304, 719, 320), Quality::Preview);
}

/// Draft on the blob at 1080p where a mask segment a few tenths of a Draft step long starts
/// or ends at a face as dense as the shell behind it: pixel (733, 1000)'s density falls
/// from ~3000 at the face to ~600 within a step a sixteenth of the base one, and pixel
/// (1142, 168)'s rises from ~900 to ~4600 into the far face. Such a step is at the
/// bisection floor, yet it can hold no edge, so it is bisected: the trapezoid rule over it,
/// its error shrinking as its length cubed, is judged as any other smooth step's. Held at
/// the floor, their alpha was off by 5.7e-2 and 5.3e-2.
#[test]
fn draft_keeps_its_target_where_a_step_at_the_floor_leaves_a_dense_face() {
    assert_blob_windows_within_target(
        &[
            Window::new(725, 992, 741, 1008),
            Window::new(1134, 160, 1150, 176),
        ],
        Quality::Draft,
    );
}

/// Preview on the blob at 1080p where a ray grazes a mask and its segment there is one step
/// long, both ends dense (~60 at pixel (562, 792), ~30 at (1267, 232), ~87 at the end of
/// (901, 1000)): the step has no neighbour to measure a curvature through, and its ends'
/// jump does not bound the dip or bump between them; it is judged by its denser end (as a
/// trained field's step of an exact run is). Judged by the jump, alpha was off by 1.5e-2,
/// 1.0e-2 and 9.4e-3.
#[test]
fn preview_keeps_its_target_where_a_smooth_mask_segment_is_one_step_long() {
    assert_blob_windows_within_target(
        &[
            Window::new(554, 784, 570, 800),
            Window::new(1259, 224, 1275, 240),
            Window::new(893, 992, 909, 1008),
        ],
        Quality::Preview,
    );
}

/// Final and Preview on the blob at 1080p where a bump lies in a round's first step: the
/// nodes before it went with the round before, so its curvature is measured on one side
/// only, where the density falls away, while the rise into it lay in that round. Judged by
/// that side, Final's alpha at pixels (1360, 424) and (1345, 392) was off by 1.3e-3 and
/// 1.2e-3, and Preview's green at (1205, 200) by 7.6e-3; judged by the larger of its jump
/// and that side (as a trained field's step of an exact run is), within target. Pixel
/// (1360, 424) is held on its row: 3 pixels left and 2 down, (1357, 426) is off by 1.05e-3
/// in alpha from some 150 steps' small errors adding up (the trapezoid rule's bias on a
/// convex density, each step's well within its estimate), which no one step's rule can see.
#[test]
fn a_rounds_first_step_is_judged_by_its_jump_too() {
    assert_blob_window_within_target(Window::new(1352, 424, 1368, 425), Quality::Final);
    assert_blob_window_within_target(Window::new(1337, 384, 1353, 400), Quality::Final);
    assert_blob_window_within_target(Window::new(1197, 192, 1213, 208), Quality::Preview);
}

/// Preview on the blob at 1080p where a later round's first step, longer than the field's
/// smooth length, straddles a peak far denser than any node of its round: at pixel
/// (650, 266) a step of 1.9 smooth lengths between nodes of 107 and 63 (the round's densest
/// 107) held a peak of 2700 (optical depth 1.41, the trapezoid's 0.23), and alpha was off by
/// 9.2e-3; at (1133, 918) and (1238, 846) by 6.5e-3 and 5.1e-3. The step's shell is as
/// dense as the densest node of the ray's rounds so far (there 1183), not of its round only.
#[test]
fn preview_keeps_its_target_where_a_rounds_first_step_straddles_a_dense_peak() {
    assert_blob_windows_within_target(
        &[
            Window::new(642, 258, 658, 274),
            Window::new(1125, 910, 1141, 926),
            Window::new(1230, 838, 1246, 854),
        ],
        Quality::Preview,
    );
}

/// Final on the blob at 1080p where a mask segment's last step lies alone in its round:
/// at pixel (791, 1010) a step between ends of 154 and 153 held a dip to 143 (the step's
/// error 2.8e-3 in optical depth), which its jump did not show, and alpha was off by
/// 1.12e-3; it is judged by its denser end, as a segment one step long is.
#[test]
fn final_keeps_its_target_where_a_segments_last_step_is_alone_in_its_round() {
    assert_blob_window_within_target(Window::new(783, 1002, 799, 1018), Quality::Final);
}

/// Final on the blob at 1080p at the bench rows' worst pixels, where no one step misses its
/// estimate: at (1357, 426) and (546, 586) some 150 and 120 steps' trapezoid errors, each
/// well within its estimate, add up over a convex trained surface (2.9e-3 and 2.5e-3 of
/// optical depth, weighted by the transmittance, too much against 1.1e-3 and 9.5e-4 too
/// little), and alpha was off by 1.05e-3 and 1.01e-3. The pieces are composited less the
/// bias their curvature predicts.
#[test]
fn final_keeps_its_target_where_many_small_trapezoid_errors_add_up() {
    assert_blob_windows_within_target(
        &[
            Window::new(1349, 418, 1365, 434),
            Window::new(538, 578, 554, 594),
        ],
        Quality::Final,
    );
}

/// Final on the blob at 480×270 where steps straddle dips and bumps narrower than the
/// field's smooth length that their nodes do not show: at pixel (339, 106) two steps' errors,
/// each within its estimate (0.86 and 0.88 of it), added with one sign, and alpha was off by
/// 1.01e-3. A smooth step is bisected once its estimate reaches 9/10 of the target.
#[test]
fn final_keeps_its_target_where_steps_straddle_narrow_bumps() {
    assert_blob_window_within_target_at((480, 270), Window::new(331, 98, 347, 114), Quality::Final);
}

/// Renders `window` of the bench's dense blob at 1920×1080 at `quality` and holds it to the
/// preset's error target against the quadrature reference (and prints its errors).
fn assert_blob_window_within_target(window: Window, quality: Quality) {
    assert_blob_window_within_target_at((1920, 1080), window, quality);
}

/// [`assert_blob_window_within_target`] with the blob rendered at `width × height`.
fn assert_blob_window_within_target_at(
    (width, height): (u32, u32),
    window: Window,
    quality: Quality,
) {
    let dir = tempfile::tempdir().unwrap();
    let bench = build(SceneKind::Blob, width, height, dir.path(), None).expect("the blob");
    let want = nerfx_testkit::reference::render_trained(
        &bench.scene,
        &bench.camera,
        window,
        QUADRATURE_TOLERANCE,
    )
    .expect("the quadrature");
    let params = marched(quality.params());
    let settings = RenderSettings::new(params, Outputs::all());
    let got = render(&bench.scene, &bench.camera, window, &settings).expect("a render");
    let what = format!("blob at {width}×{height}, {quality:?}");
    let errors = nerfx_testkit::reference::ErrorReport::compare(&want, &got);
    println!(
        "{what}, {window:?}: max alpha error {:.2e}, max colour error {:.2e}",
        errors.max_alpha_error, errors.max_color_error
    );
    assert_sane(&what, &got);
    assert_close(&what, &got, &want, within_target(params));
}

/// [`assert_blob_window_within_target`] for each of `windows`.
fn assert_blob_windows_within_target(windows: &[Window], quality: Quality) {
    for &window in windows {
        assert_blob_window_within_target(window, quality);
    }
}

/// A preset's promise: every pixel's alpha and premultiplied colour channels within its
/// error target (depth is not part of it).
fn within_target(params: MarchParams) -> Tol {
    let target = f64::from(params.error_target);
    Tol {
        min_psnr: 0.0,
        min_alpha_psnr: 0.0,
        rgb: target,
        alpha: target,
        depth_rel: f64::INFINITY,
    }
}

/// A box of constant density seen whole: its span is one piece, so every ray that crosses
/// it takes one density sample and at most one colour sample (none where its weight is
/// within the colour-skip budget), none elsewhere, and its alpha is the closed form
/// `1 − e^{−k·L}` (chord length `L`) to rounding.
#[test]
fn a_constant_span_takes_one_sample() {
    let scene = Scene::new(vec![instance(
        "box",
        vec![prim(cube([-1.0; 3], [1.0; 3]), 0.7, [0.9, 0.5, 0.2])],
        DMat4::from_rotation_z(0.4),
        None,
    )]);
    let camera = camera_at(DVec3::new(4.0, -5.0, 3.0), DVec3::ZERO, 48, 36, 35.0);
    let want = reference_full(&scene, &camera);
    let (got, stats) = render_final(&scene, &camera);
    let crossing = covered(&want) as u64;
    assert!(crossing > 100, "the box must be in view");
    assert_eq!(stats.density_samples, crossing);
    assert!(stats.color_samples <= crossing && stats.color_samples > crossing / 2);
    let tight = Tol {
        min_psnr: 100.0,
        min_alpha_psnr: 100.0,
        rgb: 1e-5,
        alpha: 1e-5,
        depth_rel: 1e-5,
    };
    assert_close("one box", &got, &want, tight);
}

/// A Gaussian seen whole is two exact runs, one each side of its peak along the ray, with no
/// edge inside: their steps are as long as the trapezoid rule's error estimate allows at
/// Final's target, so a ray crossing it takes a few times fewer density samples than the
/// ball's diameter holds base steps (148 here), and the image stays within Final's error
/// target (1e-3 in alpha and each colour channel) against the closed form.
#[test]
fn a_gaussian_is_marched_in_steps_its_curvature_allows() {
    let (sigma, cutoff) = (0.5, 4.0);
    let gaussian = prim(
        Shape::Gaussian {
            center: Vec3::ZERO,
            sigma,
            cutoff,
        },
        2.0,
        [0.4, 0.6, 0.9],
    );
    let field = Analytic {
        primitives: vec![gaussian],
    };
    let scene = Scene::new(vec![instance(
        "haze",
        vec![gaussian],
        DMat4::IDENTITY,
        None,
    )]);
    let camera = camera_at(DVec3::new(0.0, -7.0, 0.0), DVec3::ZERO, 48, 36, 40.0);
    let want = reference_full(&scene, &camera);
    let params = marched(Quality::Final.params());
    let (got, stats) = render_final(&scene, &camera);
    let crossing = covered(&want) as f64;
    assert!(crossing > 500.0, "the Gaussian must fill much of the view");
    let base = f64::from(field.feature_size() / params.steps_per_feature);
    let diameter_steps = f64::from(2.0 * cutoff * sigma) / base;
    let per_ray = stats.density_samples as f64 / crossing;
    assert!(
        per_ray < diameter_steps / 4.0,
        "{per_ray:.1} samples per ray, the diameter holds {diameter_steps:.0} base steps"
    );
    let target = Tol {
        min_psnr: 60.0,
        min_alpha_psnr: 60.0,
        rgb: 1e-3,
        alpha: 1e-3,
        depth_rel: 1e-2,
    };
    assert_close("one Gaussian", &got, &want, target);
}

/// A Final render of the whole view, with its statistics.
fn render_final(scene: &Scene, camera: &Camera) -> (Planes, RenderStats) {
    let settings = RenderSettings::new(marched(Quality::Final.params()), Outputs::all());
    render_with_progress(scene, camera, camera.full_window(), &settings, &|_| {}).expect("render")
}

/// The pixels with any coverage in a reference.
fn covered(planes: &Planes) -> usize {
    let alpha = planes.alpha.as_ref().expect("alpha");
    alpha.data.iter().filter(|&&a| a > 0.0).count()
}

/// A seeded scene and camera that fill most of a 64×48 image.
fn seeded_view(seed: u64) -> (Scene, Camera) {
    let mut rng = SplitMix64::new(seed);
    let scene = random_scene(&mut rng);
    let camera = random_camera(&mut rng, W, H);
    (scene, camera)
}

fn render_tiled(scene: &Scene, camera: &Camera, window: Window, tile_size: u32) -> Planes {
    let settings = RenderSettings {
        tile_size,
        ..RenderSettings::new(marched(Quality::Final.params()), Outputs::all())
    };
    render(scene, camera, window, &settings).expect("render")
}

/// nerfacc's "packed and per-ray layouts agree": a tile batches its rays' field queries, so
/// a ray must come out the same whether it is marched alone (tile 1) or with 48 others.
#[test]
fn tiles_of_any_size_give_identical_pixels() {
    let (scene, camera) = seeded_view(3);
    let window = Window::new(5, 3, 59, 41);
    let alone = render_tiled(&scene, &camera, window, 1);
    assert_sane("tile 1", &alone);
    assert!(
        alone
            .alpha
            .as_ref()
            .is_some_and(|a| a.data.iter().any(|&v| v > 0.5)),
        "the window must see the scene"
    );
    for size in [7, 16, 64] {
        let tiled = render_tiled(&scene, &camera, window, size);
        assert_close(
            &format!("tile {size} vs tile 1"),
            &tiled,
            &alone,
            Tol::EXACT,
        );
    }
}

#[test]
fn a_sub_window_equals_the_same_region_of_the_full_render() {
    let (scene, camera) = seeded_view(5);
    let full = render_tiled(&scene, &camera, camera.full_window(), 16);
    for window in [
        Window::new(5, 3, 59, 41),
        Window::new(13, 9, 14, 10),
        Window::new(0, 20, W, 29),
        // Clamped to the image.
        Window::new(40, 30, 1000, 1000),
    ] {
        let part = render_tiled(&scene, &camera, window, 16);
        let clamped = window.intersect(&camera.full_window());
        assert_close(
            &format!("window {window:?}"),
            &part,
            &crop_planes(&full, clamped),
            Tol::EXACT,
        );
    }
}

/// `window` of the full image `planes`, cut out.
fn crop_planes(planes: &Planes, window: Window) -> Planes {
    let cut = |p: &Plane| Plane {
        width: window.width(),
        height: window.height(),
        data: (window.y0..window.y1)
            .flat_map(|y| (window.x0..window.x1).map(move |x| p.get(x, y)))
            .collect(),
    };
    Planes {
        width: window.width(),
        height: window.height(),
        rgb: planes
            .rgb
            .as_ref()
            .map(|c| [cut(&c[0]), cut(&c[1]), cut(&c[2])]),
        alpha: planes.alpha.as_ref().map(cut),
        depth_z: planes.depth_z.as_ref().map(cut),
        depth_ray: planes.depth_ray.as_ref().map(cut),
        depth_median: planes.depth_median.as_ref().map(cut),
    }
}

/// Planes of `width × height` with every sample `value` (and `rgb` in every colour plane).
fn filled(width: u32, height: u32, rgb: f32, alpha: f32, depth: f32) -> Planes {
    let p = |v| Plane::filled(width, height, v);
    Planes {
        width,
        height,
        rgb: Some([p(rgb), p(rgb), p(rgb)]),
        alpha: Some(p(alpha)),
        depth_z: Some(p(depth)),
        depth_ray: Some(p(depth)),
        depth_median: Some(p(depth)),
    }
}

/// nerfacc's "ray with no samples": rays that meet no instance's bounds, and rays that cross
/// bounds but no density, are transparent black with infinite depth in every plane.
#[test]
fn rays_with_no_samples_are_empty() {
    let (scene, _) = seeded_view(1);
    let away = camera_at(
        DVec3::new(0.0, 10.0, 0.0),
        DVec3::new(0.0, 20.0, 0.0),
        W,
        H,
        50.0,
    );
    let empty = filled(W, H, 0.0, 0.0, f32::INFINITY);
    for quality in Quality::ALL {
        let got = render_full(&scene, &away, marched(quality.params()));
        assert_close(
            &format!("{quality:?}, looking away"),
            &got,
            &empty,
            Tol::EXACT,
        );
    }
    let (naive, _) =
        render_naive(&scene, &away, away.full_window(), 0.01, &Outputs::all()).expect("naive");
    assert_close("naive, looking away", &naive, &empty, Tol::EXACT);
    // Inside the bounds of a hollow field: two spheres, the camera between them looking at
    // the empty space in the middle of the bounding box.
    let hollow = Scene::new(vec![instance(
        "hollow",
        vec![
            prim(sphere([-4.0, 0.0, 0.0], 0.5), 50.0, [1.0, 0.0, 0.0]),
            prim(sphere([4.0, 0.0, 4.0], 0.5), 50.0, [0.0, 1.0, 0.0]),
        ],
        DMat4::IDENTITY,
        None,
    )]);
    let between = camera_at(
        DVec3::new(0.0, -0.4, 2.0),
        DVec3::new(0.0, 0.4, 2.0),
        16,
        12,
        20.0,
    );
    let got = render_full(&hollow, &between, marched(Quality::Final.params()));
    assert_close(
        "inside empty bounds",
        &got,
        &filled(16, 12, 0.0, 0.0, f32::INFINITY),
        Tol::EXACT,
    );
}

/// Work for planes nobody asked for is not done — and leaving it out changes nothing else.
#[test]
fn requesting_fewer_outputs_changes_nothing_in_the_rest() {
    let (scene, camera) = seeded_view(7);
    let all = render_full(&scene, &camera, marched(Quality::Final.params()));
    let only = |outputs: Outputs| {
        let settings = RenderSettings::new(marched(Quality::Final.params()), outputs);
        render(&scene, &camera, camera.full_window(), &settings).expect("render")
    };
    let none = Outputs {
        rgb: false,
        alpha: false,
        depth_z: false,
        depth_ray: false,
        depth_median: false,
    };
    let alpha = only(Outputs {
        alpha: true,
        ..none
    });
    assert!(alpha.rgb.is_none() && alpha.depth_z.is_none() && alpha.depth_median.is_none());
    let subset = |p: &Planes, keep: Outputs| Planes {
        rgb: p.rgb.clone().filter(|_| keep.rgb),
        alpha: p.alpha.clone().filter(|_| keep.alpha),
        depth_z: p.depth_z.clone().filter(|_| keep.depth_z),
        depth_ray: p.depth_ray.clone().filter(|_| keep.depth_ray),
        depth_median: p.depth_median.clone().filter(|_| keep.depth_median),
        ..p.clone()
    };
    for keep in [
        Outputs {
            alpha: true,
            ..none
        },
        Outputs::rgba(),
        Outputs {
            depth_z: true,
            ..none
        },
        Outputs {
            depth_median: true,
            alpha: true,
            ..none
        },
    ] {
        let got = only(keep);
        assert_eq!(
            (
                got.rgb.is_some(),
                got.alpha.is_some(),
                got.depth_z.is_some(),
                got.depth_ray.is_some(),
                got.depth_median.is_some()
            ),
            (
                keep.rgb,
                keep.alpha,
                keep.depth_z,
                keep.depth_ray,
                keep.depth_median
            ),
            "{keep:?}: exactly the requested planes"
        );
        assert_close(&format!("{keep:?}"), &got, &subset(&all, keep), Tol::EXACT);
    }
}

/// The naive baseline converges to the reference too. It samples each step at its midpoint,
/// so a density edge of height `k` (world units) inside a step is off by up to `k·step/2` in
/// optical depth, twice per primitive crossed; with `k ≤ 200/0.6` (the smallest instance
/// scale) and step 2.5e-4 that is 0.083 per ray in the worst case. A loose bound, as for
/// any uniform marcher: alpha 0.1, RGB 0.1, PSNR 50 dB, depth 1e-2.
#[test]
fn naive_with_a_fine_step_converges_to_the_reference() {
    let (scene, camera) = seeded_view(2);
    let window = Window::new(16, 12, 48, 36);
    let want = nerfx_testkit::reference::render(&scene, &camera, window).expect("reference");
    let (got, _) = render_naive(&scene, &camera, window, 2.5e-4, &Outputs::all()).expect("naive");
    assert_sane("naive", &got);
    assert_close(
        "naive, step 2.5e-4",
        &got,
        &want,
        Tol {
            min_psnr: 50.0,
            min_alpha_psnr: 45.0,
            rgb: 0.1,
            alpha: 0.1,
            depth_rel: 1e-2,
        },
    );
}

/// `a` over `b`, premultiplied: `C = C_a + (1 − α_a)·C_b`, `α = α_a + (1 − α_a)·α_b`.
fn over(a: &Planes, b: &Planes) -> Planes {
    let (aa, ab) = (
        a.alpha.as_ref().expect("alpha"),
        b.alpha.as_ref().expect("alpha"),
    );
    let mix = |pa: &Plane, pb: &Plane| Plane {
        data: pa
            .data
            .iter()
            .zip(&pb.data)
            .zip(&aa.data)
            .map(|((&x, &y), &alpha)| x + (1.0 - alpha) * y)
            .collect(),
        ..pa.clone()
    };
    let (ca, cb) = (a.rgb.as_ref().expect("rgb"), b.rgb.as_ref().expect("rgb"));
    Planes {
        width: a.width,
        height: a.height,
        rgb: Some([
            mix(&ca[0], &cb[0]),
            mix(&ca[1], &cb[1]),
            mix(&ca[2], &cb[2]),
        ]),
        alpha: Some(mix(aa, ab)),
        depth_z: None,
        depth_ray: None,
        depth_median: None,
    }
}

/// An opaque orange sphere instance inside a semi-transparent blue box instance. Marched
/// jointly, the sphere hides the half of the box behind it and is seen through the half in
/// front, as the reference integrates; no order of compositing the two separately rendered
/// instances can give that (box over sphere counts the hidden back half of the box; sphere
/// over box drops the front half).
#[test]
fn joint_rendering_matches_the_reference_and_separate_compositing_does_not() {
    let box_inst = instance(
        "haze",
        vec![prim(cube([-1.0; 3], [1.0; 3]), 0.8, [0.2, 0.4, 0.9])],
        DMat4::from_rotation_z(0.3),
        None,
    );
    let sphere_inst = instance(
        "ball",
        vec![prim(sphere([0.0; 3], 1.0), 60.0, [1.0, 0.5, 0.1])],
        DMat4::from_scale(DVec3::splat(0.5)),
        None,
    );
    let camera = camera_at(DVec3::new(1.0, -5.0, 1.5), DVec3::ZERO, W, H, 40.0);
    let joint = Scene::new(vec![box_inst.clone(), sphere_inst.clone()]);
    let want = reference_full(&joint, &camera);
    let got = render_full(&joint, &camera, marched(Quality::Final.params()));
    assert_sane("joint", &got);
    assert_close("joint, Final", &got, &want, FINAL);

    let alone = |inst| {
        render_full(
            &Scene::new(vec![inst]),
            &camera,
            marched(Quality::Final.params()),
        )
    };
    let (haze, ball) = (alone(box_inst), alone(sphere_inst));
    let rgba = |p: &Planes| Planes {
        depth_z: None,
        depth_ray: None,
        depth_median: None,
        ..p.clone()
    };
    for (order, composite) in [
        ("box over sphere", over(&haze, &ball)),
        ("sphere over box", over(&ball, &haze)),
    ] {
        // The worst RGB error of compositing, where the sphere is in view: the haze in front
        // of it transmits e^{−0.8·(1 − 0.5)}·… of the ball, not e^{−0.8·2}; so the error is
        // tenths, against the joint march's 2e-3.
        let r = std::panic::catch_unwind(|| {
            assert_close(order, &composite, &rgba(&want), Tol { rgb: 0.05, ..FINAL })
        });
        assert!(
            r.is_err(),
            "{order}: compositing separate renders should not match the joint reference"
        );
    }
}

/// The marcher's dials beyond the presets are honoured too: a much finer step with deeper
/// refinement gets closer to the reference than Final.
#[test]
fn finer_custom_params_converge_further() {
    let (scene, camera) = seeded_view(0);
    let window = Window::new(20, 14, 44, 34);
    let want = nerfx_testkit::reference::render(&scene, &camera, window).expect("reference");
    let fine = MarchParams {
        steps_per_feature: 4.0 * Quality::Final.params().steps_per_feature,
        refine_depth: Quality::Final.params().refine_depth + 2,
        error_target: Quality::Final.params().error_target / 10.0,
        min_transmittance: 1e-6,
        color_skip_budget: 1e-7,
        ..marched(Quality::Final.params())
    };
    let settings = RenderSettings::new(fine, Outputs::all());
    let got = render(&scene, &camera, window, &settings).expect("render");
    assert_sane("fine", &got);
    // Four times finer steps, two more bisections, a tenth of the refinement tolerance: the
    // edge bound k·δ/2^(depth+1) is 16× smaller than Final's; the bounds are Final's divided
    // by 4 (PSNR + 12 dB).
    assert_close(
        "4× Final's steps, 2 more bisections",
        &got,
        &want,
        Tol {
            min_psnr: FINAL.min_psnr + 12.0,
            min_alpha_psnr: FINAL.min_alpha_psnr + 12.0,
            rgb: FINAL.rgb / 4.0,
            alpha: FINAL.alpha / 4.0,
            depth_rel: FINAL.depth_rel / 4.0,
        },
    );
}

/// A dense sheet thinner than a step inside a faint fog of the same field: the nodes on
/// either side of it both see the fog (equal, non-zero densities), so the density jump does
/// not call for a bisection; the field's density bound over the step does. (Regression: the
/// demo scene showed it at a pillar's corner inside the haze, pixel (8, 26) at 96×54: depth
/// 12.1 instead of 10.4.) Sheet offsets 0 to 12 thousandths cover a whole step
/// (feature/8 ≈ 0.0135), so some of them fall between nodes.
#[test]
fn a_dense_sheet_inside_fog_is_not_missed() {
    let p = nerfx_core::camera::Perspective::from_vertical_fov(9, 9, 10.0).expect("perspective");
    let camera = Camera::new(
        DMat4::from_translation(DVec3::new(0.3, 0.2, 5.0)),
        nerfx_core::camera::Projection::Perspective(p),
    )
    .expect("camera");
    for i in 0..=12 {
        let c = i as f32 * 1e-3;
        let scene = Scene::new(vec![instance(
            "fog with a sheet",
            vec![
                prim(cube([-1.0; 3], [1.0; 3]), 0.1, [0.2, 0.2, 0.2]),
                prim(
                    cube([-1.0, -1.0, c], [1.0, 1.0, c + 0.004]),
                    500.0,
                    [1.0, 0.2, 0.1],
                ),
            ],
            DMat4::IDENTITY,
            None,
        )]);
        let want = reference_full(&scene, &camera);
        let got = render_full(&scene, &camera, marched(Quality::Final.params()));
        assert_sane("sheet", &got);
        assert_close(&format!("sheet at z = {c}"), &got, &want, FINAL);
    }
}

/// The camera's clipping range, as Blender's: a perspective camera sees depths (camera Z,
/// not ray distance) in `[clip_start, clip_end]`. A unit sphere of σ = 2 centred 5 units
/// ahead, clip_start 5.5: the centre ray's chord runs from Z 5.5 to 6, so alpha is
/// `1 − e^{−2·0.5}` (written out here), and the marcher agrees with the reference everywhere.
#[test]
fn the_clipping_range_cuts_rays_at_constant_depth() {
    let scene = Scene::new(vec![instance(
        "sphere",
        vec![prim(sphere([0.0, 0.0, 0.0], 1.0), 2.0, [1.0, 0.5, 0.25])],
        DMat4::IDENTITY,
        None,
    )]);
    let camera = camera_at(DVec3::new(0.0, 0.0, 5.0), DVec3::ZERO, 33, 33, 30.0)
        .with_clip(5.5, 100.0)
        .expect("clip range");
    let want = reference_full(&scene, &camera);
    let got = render_full(&scene, &camera, marched(Quality::Final.params()));
    assert_sane("clipped", &got);
    assert_close("clipped", &got, &want, FINAL);
    let centre = want.alpha.as_ref().expect("alpha").get(16, 16) as f64;
    assert!((centre - (1.0 - (-1.0f64).exp())).abs() < 1e-6, "{centre}");
    // Off-axis rays are cut at the same depth, i.e. at a longer distance: their Z is ≥ 5.5.
    let z = got.depth_z.as_ref().expect("depth");
    for y in 0..33 {
        for x in 0..33 {
            let d = z.get(x, y);
            assert!(d.is_infinite() || d >= 5.5, "({x}, {y}): {d}");
        }
    }
}
