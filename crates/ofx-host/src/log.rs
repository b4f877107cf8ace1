//! What a plugin did that a test wants to see afterwards: the messages it posted and every
//! strictness violation the host caught. Each [`super::Bundle`] has its own log; suite calls
//! that cannot name their object (a bad handle, a message on a null handle) go to the log of
//! the action running on the calling thread ([`current`]), else to a process-wide log that
//! every bundle reports too.

use std::cell::RefCell;
use std::sync::{Arc, Mutex, OnceLock, PoisonError};

use openfx_sys as ofx;

use super::spec::cstr;

/// A message the plugin posted through the message suite.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Message {
    /// The message type (`OfxMessageError`, `OfxMessageWarning`, …).
    pub kind: String,
    /// The formatted text.
    pub text: String,
    /// Posted with `setPersistentMessage`.
    pub persistent: bool,
}

impl Message {
    /// Whether it is a warning (`kOfxMessageWarning`): the plugin went on, with something to
    /// say.
    pub fn is_warning(&self) -> bool {
        self.kind == cstr(ofx::kOfxMessageWarning)
    }
}

/// Messages and violations of one bundle.
#[derive(Debug, Default)]
pub(crate) struct Log {
    messages: Mutex<Vec<Message>>,
    violations: Mutex<Vec<String>>,
}

impl Log {
    /// Records a strictness violation.
    pub(crate) fn violation(&self, what: impl Into<String>) {
        self.violations
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(what.into());
    }

    /// Records a message, also in the running action's list (so a failed action's error can
    /// carry what the plugin said).
    pub(crate) fn message(&self, message: Message) {
        ACTION_MESSAGES.with(|m| {
            if let Some(list) = m.borrow_mut().as_mut() {
                list.push(message.text.clone());
            }
        });
        self.messages
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(message);
    }

    /// Everything recorded so far.
    pub(crate) fn messages(&self) -> Vec<Message> {
        self.messages
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// Every violation so far.
    pub(crate) fn violations(&self) -> Vec<String> {
        self.violations
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }
}

/// The process-wide log, for calls made outside any action.
pub(crate) fn orphans() -> &'static Arc<Log> {
    static ORPHANS: OnceLock<Arc<Log>> = OnceLock::new();
    ORPHANS.get_or_init(Arc::default)
}

thread_local! {
    static CURRENT: RefCell<Option<Arc<Log>>> = const { RefCell::new(None) };
    static ACTION_MESSAGES: RefCell<Option<Vec<String>>> = const { RefCell::new(None) };
}

/// The log of the action running on this thread, or the process-wide one.
pub(crate) fn current() -> Arc<Log> {
    CURRENT
        .with(|c| c.borrow().clone())
        .unwrap_or_else(|| orphans().clone())
}

/// Makes `log` this thread's current log until the guard drops, collecting the messages
/// posted meanwhile.
pub(crate) struct ActionScope {
    previous: Option<Arc<Log>>,
    previous_messages: Option<Vec<String>>,
}

impl ActionScope {
    /// Enters an action that reports to `log`.
    pub(crate) fn enter(log: Arc<Log>) -> Self {
        let previous = CURRENT.with(|c| c.replace(Some(log)));
        let previous_messages = ACTION_MESSAGES.with(|m| m.replace(Some(Vec::new())));
        ActionScope {
            previous,
            previous_messages,
        }
    }

    /// The messages posted on this thread since the scope began.
    pub(crate) fn messages(&self) -> Vec<String> {
        ACTION_MESSAGES.with(|m| m.borrow().clone().unwrap_or_default())
    }
}

impl Drop for ActionScope {
    fn drop(&mut self) {
        CURRENT.with(|c| *c.borrow_mut() = self.previous.take());
        ACTION_MESSAGES.with(|m| *m.borrow_mut() = self.previous_messages.take());
    }
}
