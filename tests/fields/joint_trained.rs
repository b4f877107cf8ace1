//! Two trained fields in one scene occlude each other: a nerfacto run placed in front of
//! another renders, jointly marched, as the two rendered apart and composited front over
//! back (exact for volumes whose densities do not overlap along a ray, which holds here:
//! each run's density is a core well inside its unit cube, nothing beyond, and the runs
//! stand apart along the view). Tested both ways round, so an order mix-up cannot pass.

use std::sync::Arc;

use crate::common_nerfacto::{scratch, write_run, Spec};
use glam::{DMat4, DVec3};
use nerfx_core::camera::{Camera, Perspective, Projection};
use nerfx_core::field::NerfactoField;
use nerfx_core::image::Planes;
use nerfx_core::render::{render, ColorOutput, Outputs, Quality, RenderSettings};
use nerfx_core::scene::{FieldHandle, Instance, Scene};

fn render_scene(instances: Vec<Instance>, camera: &Camera) -> Planes {
    let settings = RenderSettings {
        color: ColorOutput::AsTrained,
        ..RenderSettings::new(Quality::Final.params(), Outputs::rgba())
    };
    render(
        &Scene::new(instances),
        camera,
        camera.full_window(),
        &settings,
    )
    .unwrap()
}

#[test]
fn two_trained_runs_occlude_each_other_as_their_renders_composite_by_depth() {
    let dir = scratch("joint-trained");
    let runs = [
        write_run(&dir.join("a"), &Spec::core()),
        write_run(
            &dir.join("b"),
            &Spec {
                seed: 31,
                ..Spec::core()
            },
        ),
    ];
    let fields: Vec<FieldHandle> = runs
        .iter()
        .map(|run| FieldHandle::new(Arc::new(NerfactoField::load(run).unwrap())))
        .collect();
    let (w, h) = (64, 48);
    let camera = Camera::new(
        nerfx_core::demo::look_at(DVec3::new(0.0, 6.0, 0.0), DVec3::ZERO),
        Projection::Perspective(Perspective::from_vertical_fov(w, h, 40.0).unwrap()),
    )
    .unwrap();
    // Near: at the origin; far: 3 units behind it along the view, larger, and shifted sideways
    // so some pixels see one run only.
    let near = DMat4::IDENTITY;
    let far =
        DMat4::from_translation(DVec3::new(0.3, -3.0, 0.1)) * DMat4::from_scale(DVec3::splat(1.6));
    for (front, back) in [(0, 1), (1, 0)] {
        let place = |i: usize, m: DMat4| {
            Instance::new(format!("run{i}"), fields[i].clone(), m, None).unwrap()
        };
        let joint = render_scene(vec![place(front, near), place(back, far)], &camera);
        let a = render_scene(vec![place(front, near)], &camera);
        let b = render_scene(vec![place(back, far)], &camera);
        let (ja, aa, ba) = (
            joint.alpha.as_ref().unwrap(),
            a.alpha.as_ref().unwrap(),
            b.alpha.as_ref().unwrap(),
        );
        let (jc, ac, bc) = (
            joint.rgb.as_ref().unwrap(),
            a.rgb.as_ref().unwrap(),
            b.rgb.as_ref().unwrap(),
        );
        let (mut sq, mut sq_wrong, mut worst_alpha, mut both) = (0.0f64, 0.0f64, 0.0f32, 0);
        for i in 0..(w * h) as usize {
            let (fa, ba) = (aa.data[i], ba.data[i]);
            let over_alpha = fa + (1.0 - fa) * ba;
            worst_alpha = worst_alpha.max((ja.data[i] - over_alpha).abs());
            for c in 0..3 {
                let over = ac[c].data[i] + (1.0 - fa) * bc[c].data[i];
                let under = bc[c].data[i] + (1.0 - ba) * ac[c].data[i];
                sq += f64::from(jc[c].data[i] - over).powi(2);
                sq_wrong += f64::from(jc[c].data[i] - under).powi(2);
            }
            both += usize::from(fa > 0.5 && ba > 0.5);
        }
        let psnr_of = |sq: f64| -10.0 * (sq / f64::from(w * h * 3)).max(1e-30).log10();
        let (psnr, wrong) = (psnr_of(sq), psnr_of(sq_wrong));
        println!(
            "run {front} in front of run {back}: RGB PSNR {psnr:.1} dB against front over \
             back ({wrong:.1} dB against back over front), alpha within {worst_alpha:.2e}; \
             {both} pixels where both cover"
        );
        // The check can fail: where both cover, the order shows.
        assert!(
            both > 100,
            "the runs barely overlap in view ({both} pixels)"
        );
        assert!(wrong < 30.0, "back over front is as close ({wrong:.1} dB)");
        assert!(psnr >= 40.0, "RGB PSNR {psnr:.1} dB");
        assert!(worst_alpha <= 1e-2, "alpha off by {worst_alpha:.2e}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
