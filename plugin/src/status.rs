//! OpenFX status codes and the plugin's one failure type.
//!
//! The bindings carry only `kOfxStatOK`: the other codes are `((int) n)` macros that bindgen
//! does not translate, so their values (ofxCore.h, ofxImageEffect.h) are restated here.
//! Every error the plugin meets, from the core or from a host call, becomes a [`Failure`]:
//! a status to return and a text for the host's message suite.

use std::fmt;

use openfx_sys::OfxStatus;

/// The action succeeded.
pub const OK: OfxStatus = 0;
/// Something went wrong; the plugin has posted a message.
pub const FAILED: OfxStatus = 1;
/// The host lacks a suite the plugin needs.
pub const ERR_MISSING_HOST_FEATURE: OfxStatus = 4;
/// The host asked for something the plugin does not support (an unknown context).
pub const ERR_UNSUPPORTED: OfxStatus = 5;
/// The host ran out of memory; the host may purge and retry.
pub const ERR_MEMORY: OfxStatus = 8;
/// The action was not trapped: the host applies its default.
pub const REPLY_DEFAULT: OfxStatus = 14;

/// Why an action failed: the status to return and what to tell the artist.
#[derive(Debug)]
pub struct Failure {
    /// The status the action returns.
    pub status: OfxStatus,
    /// The message posted through the host's message suite (names file, field, frame,
    /// node and parameter where the core's error does).
    pub message: String,
}

impl Failure {
    /// A failure with status [`FAILED`].
    pub fn failed(message: impl Into<String>) -> Self {
        Failure {
            status: FAILED,
            message: message.into(),
        }
    }

    /// A host call `call` that answered `status`; out-of-memory is passed on as such so the
    /// host can purge its caches and retry, everything else is [`FAILED`].
    pub fn host(call: impl fmt::Display, status: OfxStatus) -> Self {
        Failure {
            status: if status == ERR_MEMORY {
                ERR_MEMORY
            } else {
                FAILED
            },
            message: format!("host call {call} answered status {status}"),
        }
    }

    /// The host does not offer `suite` (or does not offer it in the version needed).
    pub fn missing_suite(suite: &str) -> Self {
        Failure {
            status: ERR_MISSING_HOST_FEATURE,
            message: format!("the host does not offer the {suite}"),
        }
    }
}

impl From<nerfx_core::Error> for Failure {
    fn from(e: nerfx_core::Error) -> Self {
        Failure::failed(e.to_string())
    }
}

impl fmt::Display for Failure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

/// Results of the plugin's actions.
pub type Result<T, E = Failure> = std::result::Result<T, E>;

/// Turns a host call's status into a result, naming the call on failure.
pub fn check(call: impl fmt::Display, status: OfxStatus) -> Result<()> {
    if status == OK {
        Ok(())
    } else {
        Err(Failure::host(call, status))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_match_the_headers_values() {
        // ofxCore.h: kOfxStatFailed 1, kOfxStatErrMissingHostFeature 4,
        // kOfxStatErrUnsupported 5, kOfxStatErrMemory 8, kOfxStatReplyDefault 14.
        assert_eq!(openfx_sys::kOfxStatOK as OfxStatus, OK);
        assert_eq!(
            (FAILED, ERR_MISSING_HOST_FEATURE, ERR_UNSUPPORTED),
            (1, 4, 5)
        );
        assert_eq!((ERR_MEMORY, REPLY_DEFAULT), (8, 14));
    }

    #[test]
    fn host_failures_keep_out_of_memory() {
        assert_eq!(Failure::host("clipGetImage(A)", 8).status, ERR_MEMORY);
        let f = Failure::host("clipGetImage(A)", 9);
        assert_eq!(f.status, FAILED);
        assert!(f.message.contains("clipGetImage(A)") && f.message.contains('9'));
        assert!(check("x", OK).is_ok());
    }
}
