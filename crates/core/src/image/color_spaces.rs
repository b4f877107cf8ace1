//! Output colour spaces: what the colour of a written image means.
//!
//! nerfx renders scene-linear Rec.709 (sRGB primaries, D65 white). An image may be written in
//! another space instead: the linear spaces of an ACES pipeline (ACEScg, ACES2065-1), wide-gamut
//! linear Rec.2020 and P3-D65, or display-encoded sRGB for previews.
//!
//! Every linear conversion is one 3×3 matrix, built from the standards' primaries and white
//! points: `M = XYZ→RGB(target) · CAT(D65 → target white) · RGB→XYZ(Rec.709)`, where the
//! chromatic adaptation is the linear Bradford transform, as ACES specifies (and OpenColorIO's
//! built-in configurations use) between D65 and the ACES white (≈ D60, x 0.32168, y 0.33767).
//! A matrix is linear, so it applies to premultiplied colour as it is. The sRGB encoding is
//! not: it applies to unpremultiplied colour, which is premultiplied again after (IEC 61966-2-1's
//! curve, continued linearly below zero as OpenColorIO does).
//!
//! Worked number: pure linear Rec.709 red `(1, 0, 0)` is `(0.6131, 0.0702, 0.0206)` in ACEScg.

use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::image::{DeepImage, Planes};

/// CIE 1931 xy chromaticities of a colour space's red, green and blue primaries and its white
/// point: what an EXR's `chromaticities` attribute holds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Chromaticities {
    /// Red primary `(x, y)`.
    pub red: [f64; 2],
    /// Green primary `(x, y)`.
    pub green: [f64; 2],
    /// Blue primary `(x, y)`.
    pub blue: [f64; 2],
    /// White point `(x, y)`.
    pub white: [f64; 2],
}

/// D65 (ITU-R BT.709, BT.2020, SMPTE EG 432-1 for P3-D65).
const D65: [f64; 2] = [0.3127, 0.3290];
/// The ACES white (SMPTE ST 2065-1), close to D60.
const ACES_WHITE: [f64; 2] = [0.32168, 0.33767];

const REC709: Chromaticities = Chromaticities {
    red: [0.64, 0.33],
    green: [0.30, 0.60],
    blue: [0.15, 0.06],
    white: D65,
};
const AP1: Chromaticities = Chromaticities {
    red: [0.713, 0.293],
    green: [0.165, 0.830],
    blue: [0.128, 0.044],
    white: ACES_WHITE,
};
const AP0: Chromaticities = Chromaticities {
    red: [0.7347, 0.2653],
    green: [0.0, 1.0],
    blue: [0.0001, -0.0770],
    white: ACES_WHITE,
};
const REC2020: Chromaticities = Chromaticities {
    red: [0.708, 0.292],
    green: [0.170, 0.797],
    blue: [0.131, 0.046],
    white: D65,
};
const P3_D65: Chromaticities = Chromaticities {
    red: [0.680, 0.320],
    green: [0.265, 0.690],
    blue: [0.150, 0.060],
    white: D65,
};

/// The colour space an image is written in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum OutputColorSpace {
    /// Scene-linear Rec.709 primaries, D65 white: what nerfx renders.
    #[default]
    #[serde(rename = "lin_rec709")]
    #[cfg_attr(feature = "clap", value(name = "lin_rec709"))]
    LinRec709,
    /// ACEScg: scene-linear AP1 primaries, ACES white (the CG working space of ACES).
    #[serde(rename = "acescg")]
    #[cfg_attr(feature = "clap", value(name = "acescg"))]
    AcesCg,
    /// ACES2065-1: scene-linear AP0 primaries, ACES white (the ACES archive space).
    #[serde(rename = "aces2065-1")]
    #[cfg_attr(feature = "clap", value(name = "aces2065-1"))]
    Aces2065,
    /// Scene-linear Rec.2020 primaries, D65 white.
    #[serde(rename = "lin_rec2020")]
    #[cfg_attr(feature = "clap", value(name = "lin_rec2020"))]
    LinRec2020,
    /// Scene-linear P3 primaries, D65 white.
    #[serde(rename = "lin_p3d65")]
    #[cfg_attr(feature = "clap", value(name = "lin_p3d65"))]
    LinP3D65,
    /// sRGB-encoded Rec.709 (display-referred, for previews).
    #[serde(rename = "srgb")]
    #[cfg_attr(feature = "clap", value(name = "srgb"))]
    Srgb,
}

impl OutputColorSpace {
    /// Every space, the default first.
    pub const ALL: [OutputColorSpace; 6] = [
        OutputColorSpace::LinRec709,
        OutputColorSpace::AcesCg,
        OutputColorSpace::Aces2065,
        OutputColorSpace::LinRec2020,
        OutputColorSpace::LinP3D65,
        OutputColorSpace::Srgb,
    ];

    /// The name scenes, graphs and `--colorspace` use (`lin_rec709`, `acescg`, ...).
    pub fn name(self) -> &'static str {
        match self {
            OutputColorSpace::LinRec709 => "lin_rec709",
            OutputColorSpace::AcesCg => "acescg",
            OutputColorSpace::Aces2065 => "aces2065-1",
            OutputColorSpace::LinRec2020 => "lin_rec2020",
            OutputColorSpace::LinP3D65 => "lin_p3d65",
            OutputColorSpace::Srgb => "srgb",
        }
    }

    /// The space named `name` (as [`Self::name`] spells it); `what` names the setting in the
    /// error.
    pub fn parse(name: &str, what: &str) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|s| s.name() == name)
            .ok_or_else(|| {
                let names: Vec<_> = Self::ALL.iter().map(|s| s.name()).collect();
                Error::invalid(
                    what,
                    format!(
                        "unknown colour space '{name}'; expected one of {}",
                        names.join(", ")
                    ),
                )
            })
    }

    /// The colour space's name in OpenColorIO's built-in CG configuration
    /// (`ocio://cg-config-latest`), which an `OCIOColorSpace` node offers.
    pub fn ocio_name(self) -> &'static str {
        match self {
            OutputColorSpace::LinRec709 => "Linear Rec.709 (sRGB)",
            OutputColorSpace::AcesCg => "ACEScg",
            OutputColorSpace::Aces2065 => "ACES2065-1",
            OutputColorSpace::LinRec2020 => "Linear Rec.2020",
            OutputColorSpace::LinP3D65 => "Linear P3-D65",
            OutputColorSpace::Srgb => "sRGB Encoded Rec.709 (sRGB)",
        }
    }

    /// The colour space's identifier in OpenFX's native colour management
    /// (`ofxColourspaceList.h`, the core set).
    pub fn ofx_name(self) -> &'static str {
        match self {
            OutputColorSpace::LinRec709 => "lin_rec709_srgb",
            OutputColorSpace::AcesCg => "ACEScg",
            OutputColorSpace::Aces2065 => "ACES2065-1",
            OutputColorSpace::LinRec2020 => "lin_rec2020",
            OutputColorSpace::LinP3D65 => "lin_p3d65",
            OutputColorSpace::Srgb => "srgb_tx",
        }
    }

    /// The space's primaries and white point.
    pub fn chromaticities(self) -> Chromaticities {
        match self {
            OutputColorSpace::LinRec709 | OutputColorSpace::Srgb => REC709,
            OutputColorSpace::AcesCg => AP1,
            OutputColorSpace::Aces2065 => AP0,
            OutputColorSpace::LinRec2020 => REC2020,
            OutputColorSpace::LinP3D65 => P3_D65,
        }
    }

    /// Whether colour is display-encoded (not scene-linear).
    pub(crate) fn is_display_encoded(self) -> bool {
        self == OutputColorSpace::Srgb
    }

    /// The matrix taking linear Rec.709 colour to this space's primaries (column vectors:
    /// `rgb_out = M · rgb_in`), before any encoding; exactly the identity for Rec.709's own.
    // Named as a matrix, to_from (`rgb_from_xyz`), not as a constructor.
    #[allow(clippy::wrong_self_convention)]
    pub(crate) fn from_lin_rec709(self) -> DMat3 {
        if self.chromaticities() == REC709 {
            return DMat3::IDENTITY;
        }
        rgb_from_xyz(self.chromaticities())
            * bradford(REC709.white, self.chromaticities().white)
            * xyz_from_rgb(REC709)
    }

    /// Converts one pixel of premultiplied linear Rec.709 colour with `alpha` into this
    /// space (premultiplied).
    ///
    /// ```
    /// use nerfx_core::image::OutputColorSpace;
    /// let [r, g, b] = OutputColorSpace::AcesCg.convert_pixel([1.0, 0.0, 0.0], 1.0);
    /// assert!((r - 0.6131).abs() < 1e-4 && (g - 0.0702).abs() < 1e-4 && (b - 0.0206).abs() < 1e-4);
    /// // Half coverage of linear 0.18 grey, display-encoded: 0.5 · 0.4614.
    /// let [r, ..] = OutputColorSpace::Srgb.convert_pixel([0.09; 3], 0.5);
    /// assert!((r - 0.5 * 0.461_356).abs() < 1e-5);
    /// ```
    pub fn convert_pixel(self, rgb: [f32; 3], alpha: f32) -> [f32; 3] {
        self.converter().apply(rgb, alpha)
    }

    /// Converts the colour planes of `planes` (premultiplied linear Rec.709, as a render
    /// makes them) into this space in place; alpha and depths are unchanged. Without an alpha
    /// plane colour is taken as fully covering.
    pub fn convert_planes(self, planes: &mut Planes) {
        if self == OutputColorSpace::LinRec709 {
            return;
        }
        let converter = self.converter();
        let Some([r, g, b]) = &mut planes.rgb else {
            return;
        };
        let alpha = planes.alpha.as_ref();
        for i in 0..r.data.len() {
            let a = alpha.map_or(1.0, |a| a.data[i]);
            [r.data[i], g.data[i], b.data[i]] =
                converter.apply([r.data[i], g.data[i], b.data[i]], a);
        }
    }

    /// Converts the colour of every sample of a deep image from linear Rec.709 as
    /// [`convert_planes`](Self::convert_planes) converts a pixel, each with its own alpha. A
    /// display encoding is not linear in the colours, so a deep pixel converted this way
    /// flattens near, not exactly to, the converted flat pixel: scale it there after
    /// ([`conform_to`](crate::render::conform_to)).
    pub fn convert_deep(self, deep: &mut DeepImage) {
        if self == OutputColorSpace::LinRec709 {
            return;
        }
        let converter = self.converter();
        for s in &mut deep.samples {
            s.rgb = converter.apply(s.rgb, s.alpha);
        }
    }

    fn converter(self) -> Converter {
        let m = self.from_lin_rec709();
        Converter {
            rows: [0, 1, 2].map(|i| m.row(i).to_array()),
            encode: self.is_display_encoded(),
        }
    }
}

/// One conversion, worked out once for a whole image.
struct Converter {
    rows: [[f64; 3]; 3],
    encode: bool,
}

impl Converter {
    fn apply(&self, rgb: [f32; 3], alpha: f32) -> [f32; 3] {
        let c = rgb.map(f64::from);
        let linear = self
            .rows
            .map(|row| row[0] * c[0] + row[1] * c[1] + row[2] * c[2]);
        if !self.encode {
            return linear.map(|v| v as f32);
        }
        // Encoded on unpremultiplied colour; where nothing covers the pixel, colour (if any:
        // emission) is encoded as it is.
        let a = if alpha > 0.0 { f64::from(alpha) } else { 1.0 };
        linear.map(|v| (srgb_encode(v / a) * a) as f32)
    }
}

/// The sRGB encoding (IEC 61966-2-1), its linear toe continued below zero.
fn srgb_encode(c: f64) -> f64 {
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// CIE XYZ (Y = 1) of the chromaticity `xy`.
fn xyz(xy: [f64; 2]) -> DVec3 {
    let [x, y] = xy;
    DVec3::new(x / y, 1.0, (1.0 - x - y) / y)
}

/// The matrix from linear RGB with primaries `c` to CIE XYZ: the primaries' XYZ as columns,
/// each scaled so that RGB (1, 1, 1) is the white point at Y = 1.
fn xyz_from_rgb(c: Chromaticities) -> DMat3 {
    let primaries = DMat3::from_cols(xyz(c.red), xyz(c.green), xyz(c.blue));
    let scale = primaries.inverse() * xyz(c.white);
    DMat3::from_cols(
        primaries.x_axis * scale.x,
        primaries.y_axis * scale.y,
        primaries.z_axis * scale.z,
    )
}

fn rgb_from_xyz(c: Chromaticities) -> DMat3 {
    xyz_from_rgb(c).inverse()
}

/// The linear Bradford chromatic adaptation from white `from` to white `to`, in XYZ.
fn bradford(from: [f64; 2], to: [f64; 2]) -> DMat3 {
    if from == to {
        return DMat3::IDENTITY;
    }
    // Rows of the Bradford cone-response matrix (written by rows, hence the transpose).
    let cone = DMat3::from_cols_array(&[
        0.8951, 0.2664, -0.1614, //
        -0.7502, 1.7135, 0.0367, //
        0.0389, -0.0685, 1.0296,
    ])
    .transpose();
    let (src, dst) = (cone * xyz(from), cone * xyz(to));
    cone.inverse() * DMat3::from_diagonal(dst / src) * cone
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Plane;

    #[test]
    fn white_maps_to_white_in_every_space() {
        for space in OutputColorSpace::ALL {
            let w = space.from_lin_rec709() * DVec3::ONE;
            assert!(
                (w - DVec3::ONE).abs().max_element() < 1e-12,
                "{space:?}: {w}"
            );
        }
    }

    #[test]
    fn acescg_matrix_is_the_published_one() {
        // The Rec.709 → ACEScg matrix OpenColorIO's built-in configurations hold (Bradford).
        let want = [
            [0.613_097_4, 0.339_523_1, 0.047_379_5],
            [0.070_193_7, 0.916_353_9, 0.013_452_4],
            [0.020_615_6, 0.109_569_8, 0.869_814_6],
        ];
        let m = OutputColorSpace::AcesCg.from_lin_rec709();
        for (i, row) in want.iter().enumerate() {
            for (j, &v) in row.iter().enumerate() {
                assert!(
                    (m.row(i)[j] - v).abs() < 2e-6,
                    "({i}, {j}): {}",
                    m.row(i)[j]
                );
            }
        }
    }

    #[test]
    fn names_round_trip_and_unknown_ones_are_refused() {
        for space in OutputColorSpace::ALL {
            assert_eq!(OutputColorSpace::parse(space.name(), "x").unwrap(), space);
        }
        let e = OutputColorSpace::parse("rec709", "--colorspace").unwrap_err();
        assert!(
            e.to_string().contains("--colorspace") && e.to_string().contains("acescg"),
            "{e}"
        );
    }

    #[test]
    fn srgb_encodes_unpremultiplied_colour_and_keeps_alpha() {
        let plane = |v: f32| Plane::filled(1, 1, v);
        let mut planes = Planes {
            width: 1,
            height: 1,
            rgb: Some([plane(0.09), plane(0.0), plane(0.25)]),
            alpha: Some(plane(0.5)),
            depth_z: Some(plane(3.0)),
            depth_ray: None,
            depth_median: None,
        };
        OutputColorSpace::Srgb.convert_planes(&mut planes);
        let [r, g, b] = planes.rgb.as_ref().unwrap();
        assert!((r.data[0] - 0.5 * 0.461_356).abs() < 1e-6);
        assert_eq!(g.data[0], 0.0);
        assert!((b.data[0] - 0.5 * 0.735_357).abs() < 1e-6);
        assert_eq!(planes.alpha.unwrap().data[0], 0.5);
        assert_eq!(planes.depth_z.unwrap().data[0], 3.0);
    }
}
