//! The timing [`Layer`]: every call of the server's store lands in the
//! `dend_store_seconds{op}` histogram.

use std::sync::Arc;
use std::time::Instant;

use prometheus::HistogramVec;

use crate::store::{Call, Layer, Layered, Store, StoreError};

/// Observes each call's wall time into a histogram labelled by `op`.
pub struct Timing {
    seconds: HistogramVec,
}

impl Layer for Timing {
    fn around<T>(
        &self,
        call: Call<'_>,
        f: impl FnOnce() -> Result<T, StoreError>,
    ) -> Result<T, StoreError> {
        let t0 = Instant::now();
        let r = f();
        self.seconds
            .with_label_values(&[call.op])
            .observe(t0.elapsed().as_secs_f64());
        r
    }
}

/// A store whose calls are timed.
pub type TimedStore = Layered<Timing>;

/// `inner` with each call timed into `seconds` (label `op`).
pub fn timed(inner: Arc<dyn Store>, seconds: HistogramVec) -> TimedStore {
    Layered::new(inner, Timing { seconds })
}
