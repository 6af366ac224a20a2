//! A damaged store is an error, never a crash.
//!
//! sled 0.34 panics on some damage to its files instead of returning an error (a
//! truncated log: `index out of bounds` in its segment accounting while it recovers).
//! Every call into sled goes through [`guarded`], which catches such a panic and turns
//! it into [`StoreError::Damaged`], naming the store's folder and what to do. While a
//! guarded call runs, a panic on that thread prints nothing: the process-wide panic hook
//! is wrapped once, and the wrapper stays silent for the threads inside a guarded call
//! (other threads' panics are reported by the hook that was installed before).

use super::StoreError;
use std::cell::Cell;
use std::panic::{self, AssertUnwindSafe};
use std::path::Path;
use std::sync::Once;

thread_local! {
    /// Whether this thread is inside [`guarded`].
    static GUARDED: Cell<bool> = const { Cell::new(false) };
}

static QUIET_HOOK: Once = Once::new();

/// Wrap the panic hook installed so far: silent inside a guarded call, as before elsewhere.
fn install_quiet_hook() {
    QUIET_HOOK.call_once(|| {
        let previous = panic::take_hook();
        panic::set_hook(Box::new(move |info| {
            if !GUARDED.with(Cell::get) {
                previous(info);
            }
        }));
    });
}

/// Run `call` (which reaches into sled), turning a panic into [`StoreError::Damaged`].
pub(super) fn guarded<T>(
    path: &Path,
    call: impl FnOnce() -> Result<T, StoreError>,
) -> Result<T, StoreError> {
    quietly(call).unwrap_or_else(|detail| Err(damaged(path, &detail)))
}

/// Run `call`; if it panics, nothing is printed and the panic's message is returned.
pub(super) fn quietly<T>(call: impl FnOnce() -> T) -> Result<T, String> {
    install_quiet_hook();
    let outer = GUARDED.with(|g| g.replace(true));
    let outcome = panic::catch_unwind(AssertUnwindSafe(call));
    GUARDED.with(|g| g.set(outer));
    outcome.map_err(|payload| {
        payload
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| payload.downcast_ref::<&str>().copied())
            .unwrap_or("the database failed")
            .to_owned()
    })
}

/// The error for a store whose files sled cannot read.
pub(super) fn damaged(path: &Path, detail: &str) -> StoreError {
    StoreError::Damaged {
        path: path.to_path_buf(),
        detail: detail.to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panic_inside_is_an_error_naming_the_store() {
        let path = Path::new("/data/db");
        let outcome: Result<u8, _> = guarded(path, || {
            let v: Vec<u8> = std::hint::black_box(Vec::new());
            Ok(v[3])
        });
        let message = outcome.unwrap_err().to_string();
        assert!(message.contains("/data/db"), "{message}");
        assert!(message.contains("index out of bounds"), "{message}");
        assert!(message.contains("backup"), "{message}");
        // Errors and values pass through untouched, and guards nest.
        assert_eq!(guarded(path, || guarded(path, || Ok(7))).unwrap(), 7);
        assert!(matches!(
            guarded::<()>(path, || Err(StoreError::Io("disk".into()))),
            Err(StoreError::Io(_))
        ));
        assert!(!GUARDED.with(Cell::get));
    }
}
