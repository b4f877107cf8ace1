//! What a node looks like from outside: contexts, clips, typed parameters. Plain data, so an
//! adapter (the OpenFX plugin, the graph-file reader) can describe every node generically.

/// An OpenFX context a node can be used in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Context {
    /// No inputs: the node makes an image.
    Generator,
    /// One mandatory `Source` input.
    Filter,
    /// Any inputs.
    General,
}

/// How an input clip's image is read into the planes a node's render function gets
/// (see [`crate::single_channel`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClipKind {
    /// Premultiplied RGBA (missing RGB black, missing alpha opaque when RGB is present).
    Rgba,
    /// A grey matte such as an accumulation render: the red channel, or the alpha of an
    /// alpha-only image.
    Matte,
    /// The alpha channel (a shadow-catcher render's shadow opacity).
    Alpha,
    /// Camera Z in Blender units: the depth plane when present, else red, else alpha.
    Depth,
}

/// An input clip. Every node also has one RGBA premultiplied output clip, `Output`.
#[derive(Clone, Debug, PartialEq)]
pub struct ClipDesc {
    /// Clip name (`Source`, `A`, `B`, …), unique within the node.
    pub name: &'static str,
    /// Label shown to the artist.
    pub label: &'static str,
    /// Tooltip.
    pub hint: &'static str,
    /// How its image is read.
    pub kind: ClipKind,
    /// Whether the node renders without it.
    pub optional: bool,
    /// The contexts in which the clip exists.
    pub contexts: &'static [Context],
}

/// A closed range of a numeric parameter, with the slider's narrower display range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Range {
    /// Smallest accepted value.
    pub min: f64,
    /// Largest accepted value.
    pub max: f64,
    /// Slider start.
    pub display_min: f64,
    /// Slider end.
    pub display_max: f64,
}

impl Range {
    /// A range whose slider spans all of it.
    pub const fn new(min: f64, max: f64) -> Self {
        Range {
            min,
            max,
            display_min: min,
            display_max: max,
        }
    }

    /// A range with a narrower slider.
    pub const fn display(min: f64, max: f64, display_min: f64, display_max: f64) -> Self {
        Range {
            min,
            max,
            display_min,
            display_max,
        }
    }

    /// Whether `v` is finite and inside `[min, max]`.
    pub fn contains(&self, v: f64) -> bool {
        v.is_finite() && self.min <= v && v <= self.max
    }
}

/// A parameter's type with its default (and range where it has one).
#[derive(Clone, Debug, PartialEq)]
pub enum ParamKind {
    /// A real number.
    Double {
        /// Default.
        default: f64,
        /// Accepted and display range.
        range: Range,
    },
    /// A whole number.
    Int {
        /// Default.
        default: i64,
        /// Accepted and display range (whole numbers).
        range: Range,
    },
    /// A check box.
    Bool {
        /// Default.
        default: bool,
    },
    /// One of several options, `(identifier, label)`; the value is the option's index.
    Choice {
        /// The options.
        options: &'static [(&'static str, &'static str)],
        /// Index of the default option.
        default: usize,
    },
    /// A file to read (does not animate; changing it changes the clip preferences).
    File,
    /// Free text.
    Text {
        /// Default.
        default: &'static str,
    },
    /// A colour; each component within `range`.
    Rgb {
        /// Default.
        default: [f64; 3],
        /// Range of each component.
        range: Range,
    },
    /// A colour with alpha; each component within `range`.
    Rgba {
        /// Default.
        default: [f64; 4],
        /// Range of each component.
        range: Range,
    },
    /// Three reals (a position, a size, angles).
    Double3 {
        /// Default.
        default: [f64; 3],
        /// Range of each component.
        range: Range,
    },
    /// A 4×4 matrix, 16 finite reals, row-major. OpenFX has no matrix type: the plugin
    /// publishes it as a single-line string parameter holding the 16 numbers row-major
    /// (separated by spaces or commas; its hint says so).
    Matrix {
        /// Default.
        default: [f64; 16],
    },
}

/// A parameter.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamDesc {
    /// Script name (`blackPoint`), unique within the node.
    pub name: &'static str,
    /// Label shown to the artist.
    pub label: &'static str,
    /// Tooltip.
    pub hint: &'static str,
    /// Type, default and range.
    pub kind: ParamKind,
    /// Whether it may be keyframed.
    pub animates: bool,
    /// Whether it is measured in pixels, so the render scale applies to it.
    pub spatial: bool,
}

impl ParamDesc {
    /// A parameter that animates and is not spatial (most are).
    pub const fn new(
        name: &'static str,
        label: &'static str,
        hint: &'static str,
        kind: ParamKind,
    ) -> Self {
        ParamDesc {
            name,
            label,
            hint,
            kind,
            animates: true,
            spatial: false,
        }
    }

    /// The same parameter, not animating.
    pub const fn fixed(mut self) -> Self {
        self.animates = false;
        self
    }
}

/// A node as adapters see it.
#[derive(Clone, Debug, PartialEq)]
pub struct NodeDesc {
    /// `org.nerfx.<Name>`.
    pub id: &'static str,
    /// Label shown to the artist.
    pub label: &'static str,
    /// Menu grouping (`NeRF`).
    pub group: &'static str,
    /// What the node does.
    pub hint: &'static str,
    /// Contexts it supports.
    pub contexts: &'static [Context],
    /// Input clips.
    pub clips: Vec<ClipDesc>,
    /// Parameters.
    pub params: Vec<ParamDesc>,
    /// Whether the output changes from frame to frame with unchanged inputs (a camera read
    /// from a file).
    pub frame_varying: bool,
}

impl NodeDesc {
    /// The parameter `name`.
    pub fn param(&self, name: &str) -> Option<&ParamDesc> {
        self.params.iter().find(|p| p.name == name)
    }

    /// The clip `name`.
    pub fn clip(&self, name: &str) -> Option<&ClipDesc> {
        self.clips.iter().find(|c| c.name == name)
    }
}
