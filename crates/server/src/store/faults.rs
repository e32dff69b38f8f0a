//! [`Faults`]: the fault-injection [`Layer`], for tests that need a store
//! that is slow, down, or holds a call at a gate.

use super::traits::{Call, Layer, Layered, Store};
use super::types::StoreError;
use std::sync::Arc;

/// The hook a [`Faults`] layer runs before each call.
type Hook = Box<dyn Fn(Call<'_>) -> Result<(), StoreError> + Send + Sync>;

/// Runs a hook before each call of the wrapped store: the hook may sleep
/// (a slow store), block (a gate), or fail the call (a store that is
/// down), in which case the wrapped store is not called.
pub struct Faults {
    before: Hook,
}

impl Faults {
    /// A layer running `before` ahead of each call.
    pub fn new(
        before: impl Fn(Call<'_>) -> Result<(), StoreError> + Send + Sync + 'static,
    ) -> Self {
        Faults {
            before: Box::new(before),
        }
    }
}

impl Layer for Faults {
    fn around<T>(
        &self,
        call: Call<'_>,
        f: impl FnOnce() -> Result<T, StoreError>,
    ) -> Result<T, StoreError> {
        (self.before)(call)?;
        f()
    }
}

/// A store with faults injected by `before` ahead of each call.
pub type FaultStore = Layered<Faults>;

/// `inner` with `before` run ahead of each of its calls.
pub fn with_faults(
    inner: Arc<dyn Store>,
    before: impl Fn(Call<'_>) -> Result<(), StoreError> + Send + Sync + 'static,
) -> FaultStore {
    Layered::new(inner, Faults::new(before))
}
