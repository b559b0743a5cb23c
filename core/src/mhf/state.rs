//! The MHF's values, as `semwm/mhf/state.py` holds them: object versions (tracks),
//! hypotheses and clusters (`crate::mhf::hypotheses`), and the filter's state.
//!
//! An object version is stored once, in the state's track table, and every hypothesis
//! that holds it refers to it by key (DESIGN.md's performance principle). Everything is
//! immutable once made: a scan returns a new `State` that shares with the old one every
//! version and every cluster it did not change (`Arc`), so that the states the reorder
//! window keeps cost only what changed, and a rejected batch leaves the state untouched.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use litemap::LiteMap;

use crate::mhf::hypotheses::Cluster;
use crate::mhf::rates::{Name, ObservedRates};
use crate::mhf::tables::ClassId;

/// A version's key in the track table.
pub type Key = u64;

/// The filter state of one version: `modes x size` mode-matched means, `modes x size
/// x size` covariances and `modes` mode probabilities (row-major).
#[derive(Debug, Clone, PartialEq)]
pub struct FilterState {
    pub modes: usize,
    pub size: usize,
    pub x: Vec<f64>,
    pub p: Vec<f64>,
    pub mu: Vec<f64>,
}

/// One version of one object (`Track`): its filter state after a given association
/// history.
#[derive(Debug, Clone)]
pub struct Version {
    pub key: Key,
    /// The object's identity across versions: the sequence number of the detection
    /// that created it.
    pub lineage: u64,
    /// The published class, the class whose filter tracks it.
    pub cls: ClassId,
    pub label: Option<Name>,
    pub state: Arc<FilterState>,
    /// s: when `state` holds.
    pub time: f64,
    /// s: its last detection.
    pub last_seen: f64,
    /// s: the detection that started it.
    pub created: f64,
    /// f_existing of its class (Hz), paper 002 eq. (6).
    pub rate: f64,
    /// `K`: the probability of each class being its true class.
    pub class_probs: Arc<[f64]>,
    /// The sources whose detections it took (`""` for none), sorted.
    pub sources: Arc<[Name]>,
}

impl Version {
    /// The same object as version `key` with `label` (`Track.relabeled`).
    pub fn relabeled(&self, key: Key, label: Option<Name>) -> Version {
        Version {
            key,
            label,
            ..self.clone()
        }
    }

    /// Whether `source` is among the sources whose detections it took.
    pub fn seen_by(&self, source: &str) -> bool {
        self.sources.iter().any(|s| &**s == source)
    }

    /// Its sources and `source` (the same list when it holds it).
    pub fn sources_with(&self, source: &Name) -> Arc<[Name]> {
        if self.seen_by(source) {
            return self.sources.clone();
        }
        let mut sources: Vec<Name> = self.sources.iter().cloned().collect();
        let at = sources.partition_point(|s| **s < **source);
        sources.insert(at, source.clone());
        sources.into()
    }

    /// No detection since the one that started it.
    pub fn unconfirmed(&self) -> bool {
        self.last_seen <= self.created
    }
}

/// A version in the track table, with its existence probability at the state's time
/// and a serial number that names the version for as long as the process runs (the
/// same in every state that holds it; Python caches the values it made by it).
#[derive(Debug, Clone)]
pub struct Entry {
    pub version: Arc<Version>,
    pub existence: f64,
    pub serial: u64,
}

static SERIAL: AtomicU64 = AtomicU64::new(1);

/// A serial number no entry has had.
pub fn next_serial() -> u64 {
    SERIAL.fetch_add(1, Ordering::Relaxed)
}

/// The whole filter (`MHFState`): independent clusters of hypotheses (each most probable
/// first, normalised), the track table in key order with each version's existence, the
/// time of the last scan, the next key to give, and the detection rates observed on the
/// sources' streams.
#[derive(Debug, Clone)]
pub struct State {
    pub clusters: Vec<Arc<Cluster>>,
    /// In key order: a sorted vector (built in order each scan, dropped as one block).
    pub tracks: LiteMap<Key, Entry>,
    pub time: Option<f64>,
    pub next_key: Key,
    pub observed: Arc<ObservedRates>,
}

impl State {
    pub fn empty() -> State {
        State {
            clusters: Vec::new(),
            tracks: LiteMap::new(),
            time: None,
            next_key: 0,
            observed: Arc::new(ObservedRates::default()),
        }
    }

    /// The number of hypotheses stored (the sum of the clusters').
    pub fn hypothesis_count(&self) -> usize {
        self.clusters.iter().map(|c| c.hypotheses.len()).sum()
    }

    /// A version's existence (1 for a key the table does not hold, as
    /// `state.existence.get(key, 1.0)`).
    pub fn existence(&self, key: Key) -> f64 {
        self.tracks.get(&key).map_or(1.0, |entry| entry.existence)
    }
}
