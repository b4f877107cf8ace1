//! OpenFX status codes (`OfxStatus` values, defined as macros with casts in the official
//! headers, so bindgen does not export them) and their names for error messages.

/// The status type of every suite function and action.
pub type Status = openfx_sys::OfxStatus;

/// All went well.
pub const OK: Status = 0;
/// Failed, no more specific code applies (the plugin should have posted a message).
pub const FAILED: Status = 1;
/// A fatal error.
pub const ERR_FATAL: Status = 2;
/// An unknown name (property, parameter, clip, suite).
pub const ERR_UNKNOWN: Status = 3;
/// A host feature the plugin needs is missing.
pub const ERR_MISSING_HOST_FEATURE: Status = 4;
/// Something is not supported.
pub const ERR_UNSUPPORTED: Status = 5;
/// Something already exists (a clip or parameter defined twice).
pub const ERR_EXISTS: Status = 6;
/// Bad format.
pub const ERR_FORMAT: Status = 7;
/// Out of memory.
pub const ERR_MEMORY: Status = 8;
/// A handle the host never gave out, or of the wrong kind.
pub const ERR_BAD_HANDLE: Status = 9;
/// An index out of range.
pub const ERR_BAD_INDEX: Status = 10;
/// A value of the wrong type, or an illegal value.
pub const ERR_VALUE: Status = 11;
/// Reply: yes.
pub const REPLY_YES: Status = 12;
/// Reply: no.
pub const REPLY_NO: Status = 13;
/// Reply: the action was not trapped; the host applies the default.
pub const REPLY_DEFAULT: Status = 14;
/// An image of an unsupported format.
pub const ERR_IMAGE_FORMAT: Status = 1000;

/// The name of a status, as the headers spell it (`kOfxStatFailed`), for error messages.
pub fn status_name(status: Status) -> String {
    let name = match status {
        OK => "kOfxStatOK",
        FAILED => "kOfxStatFailed",
        ERR_FATAL => "kOfxStatErrFatal",
        ERR_UNKNOWN => "kOfxStatErrUnknown",
        ERR_MISSING_HOST_FEATURE => "kOfxStatErrMissingHostFeature",
        ERR_UNSUPPORTED => "kOfxStatErrUnsupported",
        ERR_EXISTS => "kOfxStatErrExists",
        ERR_FORMAT => "kOfxStatErrFormat",
        ERR_MEMORY => "kOfxStatErrMemory",
        ERR_BAD_HANDLE => "kOfxStatErrBadHandle",
        ERR_BAD_INDEX => "kOfxStatErrBadIndex",
        ERR_VALUE => "kOfxStatErrValue",
        REPLY_YES => "kOfxStatReplyYes",
        REPLY_NO => "kOfxStatReplyNo",
        REPLY_DEFAULT => "kOfxStatReplyDefault",
        ERR_IMAGE_FORMAT => "kOfxStatErrImageFormat",
        other => return format!("status {other}"),
    };
    name.to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_follow_the_headers() {
        assert_eq!(status_name(1), "kOfxStatFailed");
        assert_eq!(status_name(14), "kOfxStatReplyDefault");
        assert_eq!(status_name(77), "status 77");
    }
}
