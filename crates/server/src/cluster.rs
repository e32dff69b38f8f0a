//! This instance's part in a shared-store deployment (docs/deployment.md).

use std::sync::Arc;
use std::time::Duration;

use crate::config::Config;

/// This instance's part in a shared-store deployment.
#[derive(Debug, Clone)]
pub struct Cluster {
    /// The instance id written in leases.
    pub instance: String,
    /// Lease lifetime.
    pub ttl: Duration,
}

impl Cluster {
    /// The instance settings from the configuration, when it names a
    /// shared store.
    pub fn from_config(config: &Config) -> Option<Arc<Cluster>> {
        config.store.as_ref()?;
        let instance = config
            .instance_id
            .clone()
            .unwrap_or_else(|| format!("dend-{}", hex::encode(rand::random::<[u8; 4]>())));
        Some(Arc::new(Cluster {
            instance,
            ttl: config.lease_ttl(),
        }))
    }
}
