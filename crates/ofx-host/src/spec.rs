//! The spec's properties, as a table: each name's type, dimension, the property sets that may
//! hold it and the ones where the plugin may write it (from the OpenFX 1.4 headers'
//! documentation of each property). The property suite checks every get and set against it.

use openfx_sys as ofx;

/// The value type of a property.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PropType {
    /// `int`.
    Int,
    /// `double`.
    Double,
    /// A C string (UTF-8).
    String,
    /// `void *`.
    Pointer,
}

/// The number of values a property holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Dim {
    /// Exactly this many.
    Fixed(usize),
    /// Any number (`X N` in the spec): the plugin may append.
    Variable,
}

/// A property set's place in the spec.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum SetKind {
    /// The host descriptor.
    Host,
    /// An image effect descriptor (describe, describeInContext).
    EffectDesc,
    /// An image effect instance.
    EffectInst,
    /// A clip descriptor.
    ClipDesc,
    /// A clip instance.
    ClipInst,
    /// An image.
    Image,
    /// A parameter descriptor.
    ParamDesc(ParamType),
    /// A parameter instance.
    ParamInst(ParamType),
    /// A parameter set.
    ParamSet,
    /// An action's arguments: exactly what the host put in; writable when `out`.
    Args {
        /// Whether these are the out-arguments.
        out: bool,
    },
}

impl SetKind {
    fn bit(self) -> u32 {
        match self {
            SetKind::Host => HOST,
            SetKind::EffectDesc => ED,
            SetKind::EffectInst => EI,
            SetKind::ClipDesc => CD,
            SetKind::ClipInst => CI,
            SetKind::Image => IM,
            SetKind::ParamDesc(_) => PD,
            SetKind::ParamInst(_) => PI,
            SetKind::ParamSet => PS,
            SetKind::Args { .. } => 0,
        }
    }

    fn param_type(self) -> Option<ParamType> {
        match self {
            SetKind::ParamDesc(t) | SetKind::ParamInst(t) => Some(t),
            _ => None,
        }
    }
}

/// An OpenFX parameter type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ParamType {
    Integer,
    Integer2D,
    Integer3D,
    Double,
    Double2D,
    Double3D,
    Rgb,
    Rgba,
    Boolean,
    Choice,
    String,
    Custom,
    Group,
    Page,
    PushButton,
}

const PARAM_TYPES: [(ParamType, &[u8]); 15] = [
    (ParamType::Integer, ofx::kOfxParamTypeInteger),
    (ParamType::Integer2D, ofx::kOfxParamTypeInteger2D),
    (ParamType::Integer3D, ofx::kOfxParamTypeInteger3D),
    (ParamType::Double, ofx::kOfxParamTypeDouble),
    (ParamType::Double2D, ofx::kOfxParamTypeDouble2D),
    (ParamType::Double3D, ofx::kOfxParamTypeDouble3D),
    (ParamType::Rgb, ofx::kOfxParamTypeRGB),
    (ParamType::Rgba, ofx::kOfxParamTypeRGBA),
    (ParamType::Boolean, ofx::kOfxParamTypeBoolean),
    (ParamType::Choice, ofx::kOfxParamTypeChoice),
    (ParamType::String, ofx::kOfxParamTypeString),
    (ParamType::Custom, ofx::kOfxParamTypeCustom),
    (ParamType::Group, ofx::kOfxParamTypeGroup),
    (ParamType::Page, ofx::kOfxParamTypePage),
    (ParamType::PushButton, ofx::kOfxParamTypePushButton),
];

impl ParamType {
    /// The type named `name` (`OfxParamTypeDouble`), if this host supports it.
    pub(crate) fn from_name(name: &str) -> Option<ParamType> {
        PARAM_TYPES
            .iter()
            .find(|(_, n)| cstr(n) == name)
            .map(|(t, _)| *t)
    }

    /// The OpenFX name of the type.
    pub(crate) fn name(self) -> &'static str {
        PARAM_TYPES
            .iter()
            .find(|(t, _)| *t == self)
            .map_or("", |(_, n)| cstr(n))
    }

    /// How its value is stored: type and number of components; `None` for types without a
    /// value (group, page, push button).
    pub(crate) fn value_shape(self) -> Option<(PropType, usize)> {
        use ParamType::*;
        Some(match self {
            Integer | Boolean | Choice => (PropType::Int, 1),
            Integer2D => (PropType::Int, 2),
            Integer3D => (PropType::Int, 3),
            Double => (PropType::Double, 1),
            Double2D => (PropType::Double, 2),
            Double3D | Rgb => (PropType::Double, 3),
            Rgba => (PropType::Double, 4),
            String | Custom => (PropType::String, 1),
            Group | Page | PushButton => return None,
        })
    }

    fn is_numeric(self) -> bool {
        use ParamType::*;
        matches!(
            self,
            Integer | Integer2D | Integer3D | Double | Double2D | Double3D | Rgb | Rgba
        )
    }

    fn is_double(self) -> bool {
        use ParamType::*;
        matches!(self, Double | Double2D | Double3D)
    }

    /// Labels of its components (`x y z`, `r g b a`), for multi-component types.
    fn dimension_labels(self) -> &'static [&'static str] {
        use ParamType::*;
        match self {
            Integer2D | Double2D => &["x", "y"],
            Integer3D | Double3D => &["x", "y", "z"],
            Rgb => &["r", "g", "b"],
            Rgba => &["r", "g", "b", "a"],
            _ => &[],
        }
    }
}

/// The text of a NUL-terminated constant from the headers.
pub(crate) const fn cstr(bytes: &'static [u8]) -> &'static str {
    match bytes.split_last() {
        Some((0, text)) => match std::str::from_utf8(text) {
            Ok(s) => s,
            Err(_) => panic!("a header constant is not UTF-8"),
        },
        _ => panic!("a header constant is not NUL-terminated"),
    }
}

/// The text of a NUL-terminated name (or of a name without the NUL).
pub(crate) fn cstr_dyn(bytes: &[u8]) -> &str {
    std::str::from_utf8(bytes.strip_suffix(&[0]).unwrap_or(bytes)).unwrap_or("")
}

const HOST: u32 = 1;
const ED: u32 = 2;
const EI: u32 = 4;
const CD: u32 = 8;
const CI: u32 = 16;
const IM: u32 = 32;
const PD: u32 = 64;
const PI: u32 = 128;
const PS: u32 = 256;
const PARAM: u32 = PD | PI;
/// Effect descriptor properties are also readable on instances (hosts copy them).
const EFFECT: u32 = ED | EI;
const CLIP: u32 = CD | CI;

/// Which parameter types a parameter property applies to.
#[derive(Clone, Copy)]
enum Applies {
    All,
    Valued,
    Numeric,
    Doubles,
    MultiDim,
    Only(ParamType),
}

impl Applies {
    fn to(self, t: ParamType) -> bool {
        match self {
            Applies::All => true,
            Applies::Valued => t.value_shape().is_some(),
            Applies::Numeric => t.is_numeric(),
            Applies::Doubles => t.is_double(),
            Applies::MultiDim => !t.dimension_labels().is_empty(),
            Applies::Only(only) => only == t,
        }
    }
}

/// A property's type: fixed, or that of its parameter's value (defaults, ranges).
#[derive(Clone, Copy)]
enum Ty {
    Is(PropType),
    ParamValue,
}

/// A property's initial value.
#[derive(Clone, Copy)]
pub(crate) enum Def {
    /// 0, 0.0, "" or NULL in every component.
    Zero,
    /// This int.
    I(i32),
    /// This double.
    D(f64),
    /// This string.
    S(&'static str),
    /// The object's name (labels, script name).
    Name,
    /// The parameter type's smallest value (ranges' minimum).
    Lowest,
    /// The parameter type's largest value.
    Highest,
    /// `x`, `y`, `z` or `r`, `g`, `b`, `a`.
    DimLabels,
}

/// One row of the table.
pub(crate) struct PropSpec {
    /// The property's name.
    pub(crate) name: &'static str,
    ty: Ty,
    dim: Dim,
    on: u32,
    writes: u32,
    pub(crate) default: Def,
    applies: Applies,
}

/// What a property is on one particular set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Resolved {
    /// Value type.
    pub(crate) ty: PropType,
    /// Dimension.
    pub(crate) dim: Dim,
    /// Whether the plugin may set it.
    pub(crate) writable: bool,
}

impl PropSpec {
    /// What the property is on a set of `kind`, or `None` when it does not belong there.
    pub(crate) fn on(&self, kind: SetKind) -> Option<Resolved> {
        if self.on & kind.bit() == 0 {
            return None;
        }
        let param = kind.param_type();
        if let Some(t) = param {
            if !self.applies.to(t) {
                return None;
            }
        }
        let (ty, dim) = match (self.ty, param) {
            (Ty::Is(ty), Some(t)) if matches!(self.default, Def::DimLabels) => {
                (ty, Dim::Fixed(t.dimension_labels().len()))
            }
            (Ty::Is(ty), _) => (ty, self.dim),
            (Ty::ParamValue, Some(t)) => {
                let (ty, n) = t.value_shape()?;
                (ty, Dim::Fixed(n))
            }
            (Ty::ParamValue, None) => return None,
        };
        Some(Resolved {
            ty,
            dim,
            writable: self.writes & kind.bit() != 0,
        })
    }
}

/// The row for `name`, if the spec defines it.
pub(crate) fn lookup(name: &str) -> Option<&'static PropSpec> {
    TABLE.iter().find(|p| p.name == name)
}

/// Every row.
pub(crate) fn all() -> &'static [PropSpec] {
    TABLE
}

/// The labels `DimLabels` stands for on a parameter type.
pub(crate) fn dimension_labels(t: ParamType) -> &'static [&'static str] {
    t.dimension_labels()
}

use Applies::All as A;
use Dim::{Fixed as F, Variable as N};
use PropType::{Double as DBL, Int as INT, Pointer as PTR, String as STR};

/// `kOfxImageEffectPropColourManagementStyle` (OpenFX 1.5, `ofxColour.h`).
pub(crate) const COLOUR_MANAGEMENT_STYLE: &[u8] = b"OfxImageEffectPropColourManagementStyle\0";
/// `kOfxImageEffectPropColourManagementNone`.
const COLOUR_MANAGEMENT_NONE: &str = "OfxImageEffectPropColourManagementNone";
/// `kOfxImageEffectPropColourManagementCore`: the style this host offers.
pub(crate) const COLOUR_MANAGEMENT_CORE: &[u8] = b"OfxImageEffectPropColourManagementCore\0";
/// `kOfxImageEffectActionGetOutputColourspace`.
pub(crate) const GET_OUTPUT_COLOURSPACE: &[u8] = b"OfxImageEffectActionGetOutputColourspace\0";
/// `kOfxImageClipPropColourspace`.
pub(crate) const CLIP_COLOURSPACE: &[u8] = b"OfxImageClipPropColourspace\0";
/// `kOfxImageClipPropPreferredColourspaces`.
pub(crate) const PREFERRED_COLOURSPACES: &[u8] = b"OfxImageClipPropPreferredColourspaces\0";

const fn row(
    name: &'static [u8],
    ty: PropType,
    dim: Dim,
    on: u32,
    writes: u32,
    default: Def,
) -> PropSpec {
    PropSpec {
        name: cstr(name),
        ty: Ty::Is(ty),
        dim,
        on,
        writes,
        default,
        applies: A,
    }
}

const fn param_row(
    name: &'static [u8],
    ty: PropType,
    dim: Dim,
    writes: u32,
    default: Def,
    applies: Applies,
) -> PropSpec {
    PropSpec {
        name: cstr(name),
        ty: Ty::Is(ty),
        dim,
        on: PARAM,
        writes,
        default,
        applies,
    }
}

const fn value_row(name: &'static [u8], default: Def, applies: Applies) -> PropSpec {
    PropSpec {
        name: cstr(name),
        ty: Ty::ParamValue,
        dim: F(1),
        on: PARAM,
        writes: PARAM,
        default,
        applies,
    }
}

use Def::{Zero as Z, D, I, S};

#[rustfmt::skip]
static TABLE: &[PropSpec] = &[
    // Common to many objects.
    row(ofx::kOfxPropType, STR, F(1), HOST | EFFECT | CLIP | IM | PARAM, 0, Z),
    row(ofx::kOfxPropName, STR, F(1), HOST | CLIP | PARAM, 0, Def::Name),
    row(ofx::kOfxPropLabel, STR, F(1), HOST | EFFECT | CLIP | PARAM, ED | CD | PARAM, Def::Name),
    row(ofx::kOfxPropShortLabel, STR, F(1), EFFECT | CLIP | PARAM, ED | CD | PARAM, Def::Name),
    row(ofx::kOfxPropLongLabel, STR, F(1), EFFECT | CLIP | PARAM, ED | CD | PARAM, Def::Name),
    row(ofx::kOfxPropIcon, STR, F(2), EFFECT | PARAM, ED | PD, Z),
    row(ofx::kOfxPropVersion, INT, N, HOST | EFFECT, ED, Z),
    row(ofx::kOfxPropVersionLabel, STR, F(1), HOST | EFFECT, ED, Z),
    row(ofx::kOfxPropAPIVersion, INT, N, HOST, 0, Z),
    row(ofx::kOfxPropPluginDescription, STR, F(1), EFFECT, ED, Z),
    row(ofx::kOfxPropHostOSHandle, PTR, F(1), HOST, 0, Z),
    row(ofx::kOfxPropInstanceData, PTR, F(1), EI, EI, Z),
    row(ofx::kOfxPropIsInteractive, INT, F(1), EI, 0, Z),
    row(ofx::kOfxPluginPropFilePath, STR, F(1), EFFECT, 0, Z),
    row(ofx::kOfxPluginPropParamPageOrder, STR, N, EFFECT, ED, Z),
    // The host.
    row(ofx::kOfxImageEffectHostPropIsBackground, INT, F(1), HOST, 0, I(1)),
    row(ofx::kOfxImageEffectPropSupportsOverlays, INT, F(1), HOST, 0, Z),
    row(ofx::kOfxImageEffectPropSetableFrameRate, INT, F(1), HOST, 0, Z),
    row(ofx::kOfxImageEffectPropSetableFielding, INT, F(1), HOST, 0, Z),
    row(ofx::kOfxImageEffectHostPropNativeOrigin, STR, F(1), HOST, 0, Z),
    row(ofx::kOfxParamHostPropSupportsCustomInteract, INT, F(1), HOST, 0, Z),
    row(ofx::kOfxParamHostPropSupportsStringAnimation, INT, F(1), HOST, 0, Z),
    row(ofx::kOfxParamHostPropSupportsChoiceAnimation, INT, F(1), HOST, 0, Z),
    row(ofx::kOfxParamHostPropSupportsBooleanAnimation, INT, F(1), HOST, 0, Z),
    row(ofx::kOfxParamHostPropSupportsCustomAnimation, INT, F(1), HOST, 0, Z),
    row(ofx::kOfxParamHostPropMaxParameters, INT, F(1), HOST, 0, I(-1)),
    row(ofx::kOfxParamHostPropMaxPages, INT, F(1), HOST, 0, Z),
    row(ofx::kOfxParamHostPropPageRowColumnCount, INT, F(2), HOST, 0, Z),
    row(ofx::kOfxImageEffectPropRenderQualityDraft, INT, F(1), HOST, 0, I(1)),
    // Plugin descriptor (and host capabilities of the same name).
    row(ofx::kOfxImageEffectPropSupportedContexts, STR, N, HOST | EFFECT, ED, Z),
    // OpenFX 1.5 colour management (ofxColour.h; not in the 1.4 headers openfx-sys binds).
    row(COLOUR_MANAGEMENT_STYLE, STR, F(1), HOST | EFFECT, ED, S(COLOUR_MANAGEMENT_NONE)),
    row(ofx::kOfxImageEffectPluginPropGrouping, STR, F(1), EFFECT, ED, Z),
    row(ofx::kOfxImageEffectPluginPropSingleInstance, INT, F(1), EFFECT, ED, Z),
    row(ofx::kOfxImageEffectPluginRenderThreadSafety, STR, F(1), EFFECT, ED, S(cstr(ofx::kOfxImageEffectRenderInstanceSafe))),
    row(ofx::kOfxImageEffectPluginPropHostFrameThreading, INT, F(1), EFFECT, ED, I(1)),
    row(ofx::kOfxImageEffectPluginPropOverlayInteractV1, PTR, F(1), EFFECT, ED, Z),
    row(ofx::kOfxImageEffectPluginPropOverlayInteractV2, PTR, F(1), EFFECT, ED, Z),
    row(ofx::kOfxImageEffectPropSupportsMultiResolution, INT, F(1), HOST | EFFECT, ED, I(1)),
    row(ofx::kOfxImageEffectPropSupportsTiles, INT, F(1), HOST | EFFECT | CLIP, ED | EI | CD, I(1)),
    row(ofx::kOfxImageEffectPropTemporalClipAccess, INT, F(1), HOST | EFFECT | CLIP, ED | CD, Z),
    row(ofx::kOfxImageEffectPropSupportedPixelDepths, STR, N, HOST | EFFECT, ED, Z),
    row(ofx::kOfxImageEffectPluginPropFieldRenderTwiceAlways, INT, F(1), EFFECT, ED, I(1)),
    row(ofx::kOfxImageEffectPropSupportsMultipleClipDepths, INT, F(1), HOST | EFFECT, ED, Z),
    row(ofx::kOfxImageEffectPropSupportsMultipleClipPARs, INT, F(1), HOST | EFFECT, ED, Z),
    row(ofx::kOfxImageEffectPropClipPreferencesSlaveParam, STR, N, EFFECT, ED, Z),
    row(ofx::kOfxImageEffectInstancePropSequentialRender, INT, F(1), HOST | EFFECT, ED | EI, Z),
    row(ofx::kOfxImageEffectPropOpenGLRenderSupported, STR, F(1), HOST | EFFECT, ED, S("false")),
    row(ofx::kOfxImageEffectPropCudaRenderSupported, STR, F(1), HOST | EFFECT, ED, S("false")),
    row(ofx::kOfxImageEffectPropCudaStreamSupported, STR, F(1), HOST | EFFECT, ED, S("false")),
    row(ofx::kOfxImageEffectPropMetalRenderSupported, STR, F(1), HOST | EFFECT, ED, S("false")),
    row(ofx::kOfxImageEffectPropOpenCLRenderSupported, STR, F(1), HOST | EFFECT, ED, S("false")),
    // Effect instance.
    row(ofx::kOfxImageEffectPropContext, STR, F(1), EI, 0, Z),
    row(ofx::kOfxImageEffectPropPluginHandle, PTR, F(1), EI, 0, Z),
    row(ofx::kOfxImageEffectPropProjectSize, DBL, F(2), EI, 0, Z),
    row(ofx::kOfxImageEffectPropProjectOffset, DBL, F(2), EI, 0, Z),
    row(ofx::kOfxImageEffectPropProjectExtent, DBL, F(2), EI, 0, Z),
    row(ofx::kOfxImageEffectPropProjectPixelAspectRatio, DBL, F(1), EI, 0, D(1.0)),
    row(ofx::kOfxImageEffectInstancePropEffectDuration, DBL, F(1), EI, 0, D(1.0)),
    row(ofx::kOfxImageEffectPropFrameRate, DBL, F(1), EI | CI, 0, D(24.0)),
    // Clips.
    row(ofx::kOfxImageEffectPropSupportedComponents, STR, N, HOST | CLIP, CD, Z),
    row(ofx::kOfxImageClipPropOptional, INT, F(1), CLIP, CD, Z),
    row(ofx::kOfxImageClipPropIsMask, INT, F(1), CLIP, CD, Z),
    row(ofx::kOfxImageClipPropFieldExtraction, STR, F(1), CLIP, CD, S(cstr(ofx::kOfxImageFieldDoubled))),
    row(ofx::kOfxImageEffectPropPixelDepth, STR, F(1), CI | IM, 0, Z),
    row(ofx::kOfxImageEffectPropComponents, STR, F(1), CI | IM, 0, Z),
    row(ofx::kOfxImageClipPropUnmappedPixelDepth, STR, F(1), CI, 0, Z),
    row(ofx::kOfxImageClipPropUnmappedComponents, STR, F(1), CI, 0, Z),
    row(ofx::kOfxImageEffectPropPreMultiplication, STR, F(1), CI | IM, 0, Z),
    row(ofx::kOfxImagePropPixelAspectRatio, DBL, F(1), CI | IM, 0, D(1.0)),
    row(ofx::kOfxImageEffectPropUnmappedFrameRate, DBL, F(1), CI, 0, D(24.0)),
    row(ofx::kOfxImageEffectPropFrameRange, DBL, F(2), CI, 0, Z),
    row(ofx::kOfxImageEffectPropUnmappedFrameRange, DBL, F(2), CI, 0, Z),
    row(ofx::kOfxImageClipPropFieldOrder, STR, F(1), CI, 0, S(cstr(ofx::kOfxImageFieldNone))),
    row(ofx::kOfxImageClipPropConnected, INT, F(1), CI, 0, Z),
    row(ofx::kOfxImageClipPropContinuousSamples, INT, F(1), CI, 0, Z),
    // Images.
    row(ofx::kOfxImageEffectPropRenderScale, DBL, F(2), IM, 0, D(1.0)),
    row(ofx::kOfxImagePropData, PTR, F(1), IM, 0, Z),
    row(ofx::kOfxImagePropBounds, INT, F(4), IM, 0, Z),
    row(ofx::kOfxImagePropRegionOfDefinition, INT, F(4), IM, 0, Z),
    row(ofx::kOfxImagePropRowBytes, INT, F(1), IM, 0, Z),
    row(ofx::kOfxImagePropField, STR, F(1), IM, 0, S(cstr(ofx::kOfxImageFieldNone))),
    row(ofx::kOfxImagePropUniqueIdentifier, STR, F(1), IM, 0, Z),
    // Parameter sets.
    row(ofx::kOfxPropParamSetNeedsSyncing, INT, F(1), PS, PS, Z),
    // Parameters.
    param_row(ofx::kOfxParamPropType, STR, F(1), 0, Z, A),
    param_row(ofx::kOfxParamPropSecret, INT, F(1), PARAM, Z, A),
    param_row(ofx::kOfxParamPropHint, STR, F(1), PARAM, Z, A),
    param_row(ofx::kOfxParamPropScriptName, STR, F(1), PD, Def::Name, A),
    param_row(ofx::kOfxParamPropParent, STR, F(1), PD, Z, A),
    param_row(ofx::kOfxParamPropEnabled, INT, F(1), PARAM, I(1), A),
    param_row(ofx::kOfxParamPropDataPtr, PTR, F(1), PI, Z, A),
    param_row(ofx::kOfxParamPropInteractV1, PTR, F(1), PD, Z, A),
    param_row(ofx::kOfxParamPropInteractSize, DBL, F(2), 0, Z, A),
    param_row(ofx::kOfxParamPropInteractSizeAspect, DBL, F(1), PD, D(1.0), A),
    param_row(ofx::kOfxParamPropInteractMinimumSize, DBL, F(2), PD, D(10.0), A),
    param_row(ofx::kOfxParamPropInteractPreferedSize, INT, F(2), PD, I(10), A),
    param_row(ofx::kOfxParamPropHasHostOverlayHandle, INT, F(1), 0, Z, A),
    param_row(ofx::kOfxParamPropUseHostOverlayHandle, INT, F(1), PD, Z, A),
    param_row(ofx::kOfxParamPropAnimates, INT, F(1), PD, I(1), Applies::Valued),
    param_row(ofx::kOfxParamPropIsAnimating, INT, F(1), 0, Z, Applies::Valued),
    param_row(ofx::kOfxParamPropIsAutoKeying, INT, F(1), 0, Z, Applies::Valued),
    param_row(ofx::kOfxParamPropPersistant, INT, F(1), PD, I(1), Applies::Valued),
    param_row(ofx::kOfxParamPropEvaluateOnChange, INT, F(1), PARAM, I(1), A),
    param_row(ofx::kOfxParamPropPluginMayWrite, INT, F(1), PD, Z, Applies::Valued),
    param_row(ofx::kOfxParamPropCanUndo, INT, F(1), PD, I(1), A),
    param_row(ofx::kOfxParamPropCacheInvalidation, STR, F(1), PD, S(cstr(ofx::kOfxParamInvalidateValueChange)), Applies::Valued),
    param_row(ofx::kOfxParamPropShowTimeMarker, INT, F(1), PARAM, Z, Applies::Valued),
    value_row(ofx::kOfxParamPropDefault, Z, Applies::Valued),
    value_row(ofx::kOfxParamPropMin, Def::Lowest, Applies::Numeric),
    value_row(ofx::kOfxParamPropMax, Def::Highest, Applies::Numeric),
    value_row(ofx::kOfxParamPropDisplayMin, Def::Lowest, Applies::Numeric),
    value_row(ofx::kOfxParamPropDisplayMax, Def::Highest, Applies::Numeric),
    param_row(ofx::kOfxParamPropIncrement, DBL, F(1), PARAM, D(1.0), Applies::Doubles),
    param_row(ofx::kOfxParamPropDigits, INT, F(1), PARAM, I(2), Applies::Doubles),
    param_row(ofx::kOfxParamPropDoubleType, STR, F(1), PD, S(cstr(ofx::kOfxParamDoubleTypePlain)), Applies::Doubles),
    param_row(ofx::kOfxParamPropDefaultCoordinateSystem, STR, F(1), PD, S(cstr(ofx::kOfxParamCoordinatesCanonical)), Applies::Doubles),
    param_row(ofx::kOfxParamPropDimensionLabel, STR, F(1), PD, Def::DimLabels, Applies::MultiDim),
    param_row(ofx::kOfxParamPropChoiceOption, STR, N, PARAM, Z, Applies::Only(ParamType::Choice)),
    param_row(ofx::kOfxParamPropStringMode, STR, F(1), PD, S(cstr(ofx::kOfxParamStringIsSingleLine)), Applies::Only(ParamType::String)),
    param_row(ofx::kOfxParamPropStringFilePathExists, INT, F(1), PD, I(1), Applies::Only(ParamType::String)),
    param_row(ofx::kOfxParamPropCustomInterpCallbackV1, PTR, F(1), PD, Z, Applies::Only(ParamType::Custom)),
    param_row(ofx::kOfxParamPropGroupOpen, INT, F(1), PD, I(1), Applies::Only(ParamType::Group)),
    param_row(ofx::kOfxParamPropPageChild, STR, N, PD, Z, Applies::Only(ParamType::Page)),
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique() {
        for (i, a) in TABLE.iter().enumerate() {
            assert!(
                TABLE[i + 1..].iter().all(|b| b.name != a.name),
                "{} twice",
                a.name
            );
        }
    }

    #[test]
    fn a_default_takes_its_parameter_type() {
        let d = lookup("OfxParamPropDefault").unwrap();
        let rgba = d.on(SetKind::ParamDesc(ParamType::Rgba)).unwrap();
        assert_eq!((rgba.ty, rgba.dim), (PropType::Double, Dim::Fixed(4)));
        let choice = d.on(SetKind::ParamInst(ParamType::Choice)).unwrap();
        assert_eq!((choice.ty, choice.dim), (PropType::Int, Dim::Fixed(1)));
        assert!(d.on(SetKind::ParamDesc(ParamType::Page)).is_none());
        assert!(d.on(SetKind::ClipDesc).is_none());
    }

    #[test]
    fn host_capabilities_are_read_only() {
        let tiles = lookup("OfxImageEffectPropSupportsTiles").unwrap();
        assert!(!tiles.on(SetKind::Host).unwrap().writable);
        assert!(tiles.on(SetKind::EffectDesc).unwrap().writable);
        assert!(tiles.on(SetKind::Image).is_none());
    }
}
