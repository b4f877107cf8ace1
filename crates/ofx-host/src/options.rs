//! How this host may behave like the hosts a plugin meets in production, chosen per
//! [`super::Bundle`] ([`super::Bundle::load_with`]). The defaults are the strict host's own
//! behaviour; every mode keeps every check (property accesses, handles, regions of interest,
//! the output's guard border) and records violations the same way.
//!
//! | option | what a real host does |
//! |---|---|
//! | [`HostOptions::message_suite`] | offers message suite V2, V1 only (older hosts), or none |
//! | [`HostOptions::rgb_inputs`] | hands RGBA clips RGB images (a host ignoring components) |
//! | [`HostOptions::padded_images`] | images stored top-down (negative row bytes), with bounds larger than asked and spare floats at each row's end |
//! | [`HostOptions::second_host`] | calls `OfxSetHost` again with another host struct |
//! | [`HostOptions::unpremultiplied_inputs`] | hands over input images with straight (unpremultiplied) colour |
//!
//! Per render or per edit rather than per bundle: [`super::Instance::render_field`] renders
//! one field of interlaced footage into a full-frame image, and
//! [`super::Instance::instance_changed_with_reason`] sends `kOfxPropChangeReason`.

/// Which message suites the host offers through `fetchSuite`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum MessageSuiteOffer {
    /// Versions 1 and 2 (persistent messages): this host's default.
    #[default]
    V2,
    /// Version 1 only: transient messages (a dialog in most hosts), no persistent ones.
    V1Only,
    /// No message suite at all: the plugin can only report through statuses.
    Absent,
}

/// Behaviour of a host, chosen per bundle. `HostOptions::default()` is the strict host.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct HostOptions {
    /// The message suite offered.
    pub message_suite: MessageSuiteOffer,
    /// Input images of clips whose components are RGBA are delivered as RGB (3 floats a
    /// pixel, `kOfxImageComponentRGB`, alpha dropped), as a host that ignores the declared
    /// components does. Alpha clips keep their one channel.
    pub rgb_inputs: bool,
    /// Every image (inputs and the output) is laid out top-down in memory, so
    /// `kOfxImagePropRowBytes` is negative and the data pointer is the bottom-left pixel in
    /// the last stored row; its bounds reach [`PADDING`] pixels past the region asked for
    /// (inputs: clipped to the input's region of definition; the output: past the render
    /// window, where the plugin must not write); and each row ends with spare floats that
    /// hold a quiet NaN.
    pub padded_images: bool,
    /// After loading, `OfxSetHost` (and each plugin's `setHost`) is called again with a
    /// second host struct, of another property-set handle, offering this message suite: the
    /// plugin must forget the suites of the first and fetch them again. `fetchSuite`
    /// through the first host afterwards is a violation.
    pub second_host: Option<MessageSuiteOffer>,
    /// Input clips and their RGBA images are unpremultiplied (straight alpha, as footage often
    /// is): `kOfxImageEffectPropPreMultiplication` says `kOfxImageUnPreMultiplied` and the
    /// colour of every pixel with alpha > 0 is divided by its alpha (pixels with alpha 0 keep
    /// their colour). A plugin must premultiply such images before compositing them.
    pub unpremultiplied_inputs: bool,
    /// How an input clip with nothing connected is presented.
    pub absent_clip: AbsentClip,
}

/// How a host presents an optional input the artist left unconnected (hosts differ).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum AbsentClip {
    /// `kOfxImageClipPropConnected` 0, and `clipGetImage` fails (the spec's way).
    #[default]
    Unconnected,
    /// Said to be connected, but `clipGetImage` fails.
    NoImage,
    /// Said to be connected, and `clipGetImage` hands out an image with no pixels (NULL
    /// data, empty bounds).
    EmptyImage,
}

/// Pixels by which [`HostOptions::padded_images`] enlarges image bounds on each side.
pub const PADDING: i64 = 2;

/// Floats at the end of each row of a [`HostOptions::padded_images`] image, after its last
/// pixel.
pub(crate) const ROW_SLACK: usize = 3;

/// One field of interlaced footage (`kOfxImageEffectPropFieldToRender`): the lower field is
/// rows 0, 2, 4… of the image counted from its bottom (`y` = 0), the upper field rows 1, 3,
/// 5….
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InterlacedField {
    /// Even rows (`kOfxImageFieldLower`).
    Lower,
    /// Odd rows (`kOfxImageFieldUpper`).
    Upper,
}

impl InterlacedField {
    /// Whether OFX row `y` (pixel coordinates, `y` up) belongs to this field.
    pub fn has_row(self, y: i64) -> bool {
        match self {
            InterlacedField::Lower => y.rem_euclid(2) == 0,
            InterlacedField::Upper => y.rem_euclid(2) == 1,
        }
    }
}

/// Why an instance changed (`kOfxPropChangeReason`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChangeReason {
    /// The artist edited it (`kOfxChangeUserEdited`).
    UserEdited,
    /// The plugin set it (`kOfxChangePluginEdited`).
    PluginEdited,
    /// The time moved, so an animated value changed (`kOfxChangeTime`).
    Time,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_are_row_parities_counted_from_the_bottom() {
        // ofxImageEffect.h: lower = rows 0, 2, 4…; upper = rows 1, 3, 5….
        assert!(
            InterlacedField::Lower.has_row(0)
                && InterlacedField::Lower.has_row(4)
                && InterlacedField::Lower.has_row(-2)
        );
        assert!(!InterlacedField::Lower.has_row(1) && !InterlacedField::Lower.has_row(-1));
        assert!(InterlacedField::Upper.has_row(1) && InterlacedField::Upper.has_row(-3));
        assert!(!InterlacedField::Upper.has_row(2));
    }

    #[test]
    fn the_default_is_the_strict_host() {
        let d = HostOptions::default();
        assert_eq!(d.message_suite, MessageSuiteOffer::V2);
        assert!(!d.rgb_inputs && !d.padded_images && d.second_host.is_none());
        assert!(!d.unpremultiplied_inputs);
    }
}
