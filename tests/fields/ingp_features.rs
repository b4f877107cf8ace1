//! The instant-ngp field's two query routes agree: density and colour asked separately, and
//! density handing its network outputs to the colour query (as the marcher asks).

use crate::common_ingp::{scratch, write_snapshot, Spec};
use glam::Vec3;
use nerfx_core::field::{Field, IngpField};

#[test]
fn the_features_route_gives_the_same_samples() {
    for (name, spec) in [("8x4", Spec::small_8x4()), ("16x2", Spec::old_16x2())] {
        let dir = scratch(&format!("features-{name}"));
        let field = IngpField::load(&write_snapshot(&dir, name, &spec)).unwrap();
        let b = field.bounds();
        let n = 1500;
        let (pts, dirs) = crate::common_fields::samples_in_box(b.min, b.max, n, 17);
        let (mut sigma, mut rgb) = (vec![0.0; n], vec![Vec3::ZERO; n]);
        field.density(&pts, &mut sigma);
        field.radiance(&pts, &dirs, &mut rgb);

        assert_eq!(field.feature_count(), 16, "{name}");
        let mut features = vec![f32::NAN; n * 16];
        let (mut sigma2, mut rgb2) = (vec![f32::NAN; n], vec![Vec3::NAN; n]);
        field.density_with_features(&pts, &mut sigma2, &mut features);
        field.radiance_with_features(&pts, &dirs, &features, &mut rgb2);

        let occupied = sigma.iter().filter(|&&s| s > 0.0).count();
        assert!(
            occupied > n / 10 && occupied < n,
            "{name}: {occupied} occupied samples"
        );
        for i in 0..n {
            let close = |a: f32, b: f32| (a - b).abs() <= 1e-6 * a.abs().max(b.abs()).max(1e-12);
            assert!(
                close(sigma2[i], sigma[i]),
                "{name} {i}: σ {} vs {}",
                sigma2[i],
                sigma[i]
            );
            // Colour only matters where there is density (elsewhere a sample has no weight).
            if sigma[i] > 0.0 {
                for k in 0..3 {
                    assert!(
                        close(rgb2[i][k], rgb[i][k]),
                        "{name} {i}: {} vs {}",
                        rgb2[i],
                        rgb[i]
                    );
                }
            }
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
