//! Results computed from the store's runs (an adaptive round's assessment), recorded under a key
//! and the fingerprint of what they were computed from, so that a replay reads them back.

use rusqlite::{OptionalExtension, params};

use super::CampaignStore;
use crate::error::Result;
use crate::outcome::unix_now;

impl CampaignStore {
    /// A result computed from the store's runs and recorded under `key` by
    /// [`CampaignStore::record_derived_result`], if one was recorded with exactly this
    /// `fingerprint` (a digest of everything the result was computed from): an expensive
    /// computation on the runs — an adaptive round's assessment — is then read back instead of
    /// repeated when a study is replayed.
    pub fn derived_result(&self, key: &str, fingerprint: &str) -> Result<Option<String>> {
        self.connection
            .query_row(
                "SELECT value FROM derived_results WHERE key = ?1 AND fingerprint = ?2",
                params![key, fingerprint],
                |r| r.get(0),
            )
            .optional()
            .map_err(|e| self.err(e))
    }

    /// Record `value`, computed from the runs, under `key` and the `fingerprint` of what it was
    /// computed from (replacing a value recorded with the same key and fingerprint).
    pub fn record_derived_result(
        &mut self,
        key: &str,
        fingerprint: &str,
        value: &str,
    ) -> Result<()> {
        let now = unix_now();
        self.connection
            .execute(
                "INSERT OR REPLACE INTO derived_results(key, fingerprint, value, created_at) VALUES (?1, ?2, ?3, ?4)",
                params![key, fingerprint, value, now],
            )
            .map(|_| ())
            .map_err(|e| self.err(e))
    }
}
