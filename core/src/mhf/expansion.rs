//! The expansion of one scan: the hypothesis algebra of
//! `MultipleHypothesisFilter.process_scan` (`semwm/mhf/filter.py`, step 5 of its module
//! docstring), from the scan's options to its clusters. The Python code is the
//! specification; each function here is named after the method it mirrors.
//!
//! Detection by detection (paper 002 Section III, paper 000 III):
//!
//! - the clusters the detection touches (the objects it may update, the objects whose
//!   presence makes a birth likelier, the holders of its label) are joined:
//!   every combination of one hypothesis from each, weights multiplied (`product`);
//! - every hypothesis is expanded into its children (eq. 1 in log space, with the
//!   priors and likelihoods of eqs. 4-8 in the options): `paper`: clutter, a new object
//!   (with F of eqs. 5-7 per parent), each gated existing object; `mht`: "new object or
//!   clutter" (one child: an object with existence `lambda_b / (lambda_b + lambda_c)`)
//!   and each gated existing object. Eq. (4): an object whose presence makes a birth
//!   likelier counts in the hypotheses that hold it, under any version. The labelling
//!   rules of paper 000 III-B: the object that takes a labelled detection holds the
//!   label, any other holder gives it up (a copy of its version without label);
//! - identical children merge and the tree is pruned (eq. 3, n_hyp,max,
//!   `crate::mhf::hypotheses`), and objects every hypothesis holds split off (`split`).
//!
//! The scan's track table is kept here as far as the algebra reads it (each version's
//! rate and label; which versions took a detection, derive from a version that existed
//! before the scan, or gave a label up); the versions this code makes (births, copies
//! without label) are returned as `Op`s, in the order their keys were given, for the
//! caller to make. Where the specification iterates over a set of objects, this code
//! iterates in ascending key order, as the specification does (`sorted`).

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use crate::error::{KernelError, KernelResult};
use crate::mhf::hypotheses::{
    checked_ln, holds, log_add, prune, replaced, with_key, Cluster, Hypothesis, KeyMap, KeySet,
    Merged, TIE,
};

/// The filter's settings the algebra reads.
#[derive(Debug, Clone, Copy)]
pub struct Settings {
    /// alpha of eq. (3) (0: no ratio pruning).
    pub ratio: f64,
    /// n_hyp,max.
    pub max_hypotheses: usize,
    /// The association model: `mht` (true) or `paper`; under `mht` hypotheses factorise
    /// over clusters, under `paper` one global cluster.
    pub mht: bool,
    /// log of `world.label_error_rate`.
    pub log_label_error: f64,
}

impl Settings {
    fn log_ratio(&self) -> f64 {
        if self.ratio > 0.0 {
            self.ratio.ln()
        } else {
            f64::NEG_INFINITY
        }
    }
}

/// What the algebra reads of an object version: f_existing (Hz) and its label (an id
/// the caller gives each distinct label).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackInfo {
    pub rate: f64,
    pub label: Option<u32>,
}

/// An object whose presence makes a birth here likelier (eq. 4): its rate and log
/// numerator.
#[derive(Debug, Clone, Copy)]
pub struct Presence {
    pub key: u64,
    pub rate: f64,
    pub log_num: f64,
}

/// An object the detection may update: its updated version, log numerator and rate
/// change.
#[derive(Debug, Clone, Copy)]
pub struct Existing {
    pub old_key: u64,
    pub updated: u64,
    pub log_num: f64,
    pub rate_change: f64,
}

/// One detection's options (`DetectionOptions`).
#[derive(Debug, Clone)]
pub struct DetectionOptions {
    pub label: Option<u32>,
    pub clutter_rate: f64,
    pub log_clutter: f64,
    /// The key and rate of the new object it would start.
    pub new_key: u64,
    pub new_track_rate: f64,
    /// The base f_new and its log numerator.
    pub new_rate: f64,
    pub new_log: f64,
    pub presence: Vec<Presence>,
    /// Sorted by `old_key`.
    pub existing: Vec<Existing>,
}

/// One option of the scan, in the scan's order.
#[derive(Debug, Clone)]
pub enum ScanOption {
    /// `SettledUpdate`: the detection updates `old_key` to `updated` for certain.
    Settled {
        old_key: u64,
        updated: u64,
    },
    /// A settled or certain update the caller made before the rest of the scan came
    /// here: its updated versions (`existing`' old and updated keys) enter the table,
    /// its cluster is already among the clusters given.
    Done(Vec<Existing>),
    Detection(DetectionOptions),
}

/// A version the expansion made, for the caller to make too.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Op {
    /// `_birth`: version `key` of the new object `from` (the same key for the first),
    /// with existence `existence`.
    Birth { key: u64, from: u64, existence: f64 },
    /// `_TrackTable.unlabeled`: version `key`, a copy of `from` without label.
    Copy { key: u64, from: u64 },
}

/// One scan's input: the clusters it may touch (with their index among the state's
/// `cluster_count` clusters), every version they hold and every version the options
/// name, and the options.
#[derive(Debug, Clone)]
pub struct Scan {
    pub settings: Settings,
    pub tracks: KeyMap<u64, TrackInfo>,
    /// Keys below it existed before the scan (`state.next_key`).
    pub first_new: u64,
    /// The next key to give (the table's, after the options took theirs).
    pub next_key: u64,
    pub clusters: Vec<(usize, Arc<Cluster>)>,
    pub cluster_count: usize,
    pub options: Vec<ScanOption>,
}

/// The scan's result: the given clusters no detection touched (their indices), the new
/// clusters in the order the filter's book holds them, the versions made and the next
/// key.
#[derive(Debug, Clone)]
pub struct Expanded {
    pub untouched: Vec<usize>,
    /// The given clusters no detection touched, in their order.
    pub untouched_clusters: Vec<Arc<Cluster>>,
    pub clusters: Vec<Arc<Cluster>>,
    pub ops: Vec<Op>,
    pub next_key: u64,
}

fn unknown(key: u64) -> KernelError {
    KernelError::Value(format!(
        "object version {key} is held by a hypothesis or named by an option but not given"
    ))
}

/// The scan's working track table (`_TrackTable`), as far as the algebra reads it.
struct Table {
    info: KeyMap<u64, TrackInfo>,
    next_key: u64,
    first_new: u64,
    by_label: KeyMap<u32, BTreeSet<u64>>,
    fresh: KeySet<u64>,
    origin: KeyMap<u64, u64>,
    derived: KeyMap<u64, Vec<u64>>,
    copies: KeyMap<u64, u64>,
    unlabeled: KeyMap<u64, u64>,
    births: KeyMap<(u64, u64), u64>,
    born: KeySet<u64>,
    ops: Vec<Op>,
}

impl Table {
    fn new(info: KeyMap<u64, TrackInfo>, first_new: u64, next_key: u64) -> Table {
        let mut by_label: KeyMap<u32, BTreeSet<u64>> = KeyMap::default();
        for (&key, track) in &info {
            if let (Some(label), true) = (track.label, key < first_new) {
                by_label.entry(label).or_default().insert(key);
            }
        }
        Table {
            info,
            next_key,
            first_new,
            by_label,
            fresh: KeySet::default(),
            origin: KeyMap::default(),
            derived: KeyMap::default(),
            copies: KeyMap::default(),
            unlabeled: KeyMap::default(),
            births: KeyMap::default(),
            born: KeySet::default(),
            ops: Vec::new(),
        }
    }

    fn get(&self, key: u64) -> KernelResult<TrackInfo> {
        self.info.get(&key).copied().ok_or_else(|| unknown(key))
    }

    fn rate(&self, key: u64) -> KernelResult<f64> {
        Ok(self.get(key)?.rate)
    }

    fn new_key(&mut self) -> u64 {
        let key = self.next_key;
        self.next_key += 1;
        key
    }

    /// `_TrackTable.add`: version `key` (its info given or made) enters the table.
    fn add(&mut self, key: u64, origin: Option<u64>, fresh: bool) -> KernelResult<()> {
        if let Some(label) = self.get(key)?.label {
            self.by_label.entry(label).or_default().insert(key);
        }
        if fresh {
            self.fresh.insert(key);
        }
        if let Some(origin) = origin {
            self.origin.insert(key, origin);
            self.derived.entry(origin).or_default().push(key);
        }
        Ok(())
    }

    /// `_TrackTable.origin_of`: the pre-scan version `key` derives from.
    fn origin_of(&self, key: u64) -> Option<u64> {
        if key < self.first_new {
            Some(key)
        } else {
            self.origin.get(&key).copied()
        }
    }

    /// `_TrackTable.unlabeled`: the version of `key` that gave its label up (paper 000
    /// III-B), made once per version.
    fn unlabeled(&mut self, key: u64) -> KernelResult<u64> {
        if let Some(&done) = self.unlabeled.get(&key) {
            return Ok(done);
        }
        let track = self.get(key)?;
        let copy = self.new_key();
        let origin = self.origin_of(key);
        let fresh = self.fresh.contains(&key);
        self.info.insert(
            copy,
            TrackInfo {
                rate: track.rate,
                label: None,
            },
        );
        self.add(copy, origin, fresh)?;
        self.ops.push(Op::Copy {
            key: copy,
            from: key,
        });
        self.unlabeled.insert(key, copy);
        if !fresh && origin == Some(key) {
            self.copies.insert(key, copy);
        }
        Ok(copy)
    }

    /// Whether version `key` holds `label`.
    fn holds_label(&self, key: u64, label: u32) -> bool {
        self.by_label
            .get(&label)
            .is_some_and(|holders| holders.contains(&key))
    }
}

/// The scan's working set of clusters (`_ClusterBook`), in the order of their ids.
struct Book {
    clusters: BTreeMap<usize, Arc<Cluster>>,
    owner: KeyMap<u64, usize>,
    next: usize,
}

impl Book {
    fn new(clusters: Vec<(usize, Arc<Cluster>)>, next: usize) -> Book {
        let held = clusters.iter().map(|(_, cluster)| cluster.keys.len()).sum();
        let mut owner = KeyMap::with_capacity_and_hasher(held, Default::default());
        for (id, cluster) in &clusters {
            for &key in &cluster.keys {
                owner.insert(key, *id);
            }
        }
        Book {
            clusters: clusters.into_iter().collect(),
            owner,
            next,
        }
    }

    fn owners(&self, keys: impl IntoIterator<Item = u64>) -> BTreeSet<usize> {
        keys.into_iter()
            .filter_map(|key| self.owner.get(&key).copied())
            .collect()
    }

    fn ids(&self) -> BTreeSet<usize> {
        self.clusters.keys().copied().collect()
    }

    fn take(&mut self, ids: &BTreeSet<usize>) -> Vec<Vec<Hypothesis>> {
        let mut taken = Vec::with_capacity(ids.len());
        for id in ids {
            if let Some(cluster) = self.clusters.remove(id) {
                for key in &cluster.keys {
                    self.owner.remove(key);
                }
                taken.push(Arc::unwrap_or_clone(cluster).hypotheses);
            }
        }
        taken
    }

    fn put(&mut self, clusters: Vec<Cluster>) {
        for cluster in clusters {
            for &key in &cluster.keys {
                self.owner.insert(key, self.next);
            }
            self.clusters.insert(self.next, Arc::new(cluster));
            self.next += 1;
        }
    }
}

/// `_product`: clusters joined, every combination of one hypothesis from each, weights
/// multiplied, pruned as the tree is (eq. 3, n_hyp,max). Combinations under eq. (3)'s
/// floor are skipped before their sets are built (the clusters hold disjoint objects,
/// so no two combinations merge).
pub fn product(
    groups: Vec<Vec<Hypothesis>>,
    ratio: f64,
    max_hypotheses: usize,
) -> KernelResult<Vec<Hypothesis>> {
    let mut groups = groups.into_iter();
    let Some(mut result) = groups.next() else {
        return Ok(vec![Hypothesis {
            log_weight: 0.0,
            keys: Vec::new(),
            rate: 0.0,
        }]);
    };
    for hypotheses in groups {
        let best = max_weight(&result) + max_weight(&hypotheses);
        let floor = if ratio > 0.0 {
            best + ratio.ln() - TIE
        } else {
            f64::NEG_INFINITY
        };
        let mut merged = Merged::with_capacity((result.len() * hypotheses.len()).min(256));
        for a in &result {
            for b in &hypotheses {
                let log_weight = a.log_weight + b.log_weight;
                if log_weight >= floor {
                    merged.add(
                        crate::mhf::hypotheses::union(&a.keys, &b.keys),
                        log_weight,
                        a.rate + b.rate,
                    );
                }
            }
        }
        result = prune(merged, ratio, max_hypotheses)?;
    }
    Ok(result)
}

/// Python's `max` over the weights: the first of the largest.
fn max_weight(hypotheses: &[Hypothesis]) -> f64 {
    let mut best = f64::NEG_INFINITY;
    for (i, h) in hypotheses.iter().enumerate() {
        if i == 0 || h.log_weight > best {
            best = h.log_weight;
        }
    }
    best
}

/// `_split`: objects held by every hypothesis are certain and become clusters of their
/// own (ascending key); a cluster whose only hypothesis is empty is dropped. Under
/// `paper` one global cluster stays.
fn split(hypotheses: Vec<Hypothesis>, table: &Table, mht: bool) -> KernelResult<Vec<Cluster>> {
    split_with(hypotheses, |key| table.rate(key), mht)
}

/// `_split` with each version's rate from `rate`.
pub fn split_with(
    hypotheses: Vec<Hypothesis>,
    rate: impl Fn(u64) -> KernelResult<f64>,
    mht: bool,
) -> KernelResult<Vec<Cluster>> {
    if !mht {
        if hypotheses.len() == 1 && hypotheses[0].keys.is_empty() {
            return Ok(Vec::new());
        }
        return Ok(vec![Cluster::of(hypotheses)]);
    }
    let mut common: Vec<u64> = hypotheses
        .first()
        .map(|h| h.keys.clone())
        .unwrap_or_default();
    for h in hypotheses.iter().skip(1) {
        common.retain(|&k| holds(&h.keys, k));
    }
    let mut result = Vec::with_capacity(common.len() + 1);
    for &key in &common {
        result.push(Cluster::certain(key, rate(key)?));
    }
    let count = hypotheses.len();
    if count > 1 && common.is_empty() {
        result.push(Cluster::of(hypotheses));
    } else if count > 1 {
        let mut common_rate = 0.0;
        for &key in &common {
            common_rate += rate(key)?;
        }
        let mut merged = Merged::with_capacity(hypotheses.len());
        for h in hypotheses {
            let keys: Vec<u64> = h.keys.into_iter().filter(|&k| !holds(&common, k)).collect();
            merged.add(keys, h.log_weight, h.rate - common_rate);
        }
        let rest = prune(merged, 0.0, count)?;
        if rest.len() > 1 || !rest[0].keys.is_empty() {
            result.push(Cluster::of(rest));
        }
    }
    Ok(result)
}

/// `_update_floor`: a log weight under which an update child of `expand` is pruned by
/// eq. (3) whatever else is built (alpha times a lower bound of the best child), or
/// `-inf` where skipping could change a result (only `mht` children with no label and
/// no label copies are each a set of objects no other child holds).
fn update_floor(
    hypotheses: &[Hypothesis],
    option: &DetectionOptions,
    copies: bool,
    settings: &Settings,
) -> f64 {
    if !settings.mht
        || settings.ratio <= 0.0
        || copies
        || option.label.is_some()
        || hypotheses.is_empty()
    {
        return f64::NEG_INFINITY;
    }
    let parent = &hypotheses[0];
    let mut best = option.log_clutter;
    for e in &option.existing {
        if holds(&parent.keys, e.old_key) && e.log_num > best {
            best = e.log_num;
        }
    }
    parent.log_weight + best + settings.log_ratio() - TIE
}

/// `_certain_update`: the cluster `expand` and `split` would give, directly, in the most
/// common case (`mht`): the detection gates exactly one object, alone and certain in
/// its cluster, and "new object or clutter" falls below eq. (3)'s floor against the
/// update: the updated object, with probability 1. `None` in every other case.
fn certain_update(
    book: &Book,
    touched: &BTreeSet<usize>,
    option: &DetectionOptions,
    table: &Table,
    settings: &Settings,
) -> KernelResult<Option<Cluster>> {
    if !settings.mht || settings.ratio <= 0.0 || touched.len() != 1 || option.existing.len() != 1 {
        return Ok(None);
    }
    if !option.presence.is_empty() || option.label.is_some() {
        return Ok(None);
    }
    let Some(cluster) = touched.first().and_then(|id| book.clusters.get(id)) else {
        return Ok(None);
    };
    if cluster.hypotheses.len() != 1 || cluster.keys.len() != 1 {
        return Ok(None);
    }
    let e = option.existing[0];
    if !holds(&cluster.keys, e.old_key) || table.copies.contains_key(&e.old_key) {
        return Ok(None);
    }
    let log_norm = cluster.hypotheses[0].log_weight;
    let log_update = log_norm + e.log_num;
    if log_update == f64::NEG_INFINITY {
        return Ok(None);
    }
    let log_unassigned = log_norm + log_add(option.log_clutter, option.new_log);
    if log_unassigned >= log_update + settings.ratio.ln() - TIE {
        return Ok(None); // both children are kept: the general path
    }
    Ok(Some(Cluster::certain(e.updated, table.rate(e.updated)?)))
}

/// `_birth`: the version a detection starts with birth weight `birth_log` (`mht`), with
/// existence `lambda_b / (lambda_b + lambda_c)`; hypotheses whose objects make a birth
/// likelier (eq. 4) start a version of their own.
fn birth(option: &DetectionOptions, birth_log: f64, table: &mut Table) -> KernelResult<u64> {
    // +0.0 makes -0.0 and 0.0 one key, as Python's float keys are
    let index = (option.new_key, (birth_log + 0.0).to_bits());
    if let Some(&born) = table.births.get(&index) {
        return Ok(born);
    }
    let log_total = log_add(option.log_clutter, birth_log);
    let first = !table.born.contains(&option.new_key);
    let born = if first {
        option.new_key
    } else {
        let key = table.new_key();
        let track = table.get(option.new_key)?;
        table.info.insert(key, track);
        key
    };
    table.add(born, None, true)?;
    table.ops.push(Op::Birth {
        key: born,
        from: option.new_key,
        existence: (birth_log - log_total).exp(),
    });
    table.births.insert(index, born);
    table.born.insert(option.new_key);
    Ok(born)
}

/// `_give_label`: the object that took the labelled detection (`holder`) holds the
/// label; any other object of the child holding it gives it up (paper 000 III-B).
fn give_label(
    child: Vec<u64>,
    holder: u64,
    label: u32,
    table: &mut Table,
) -> KernelResult<Vec<u64>> {
    let others: Vec<u64> = child
        .iter()
        .copied()
        .filter(|&k| k != holder && table.holds_label(k, label))
        .collect();
    if others.is_empty() {
        return Ok(child);
    }
    let mut result: Vec<u64> = child.into_iter().filter(|k| !others.contains(k)).collect();
    for k in others {
        let copy = table.unlabeled(k)?;
        result = with_key(&result, copy);
    }
    Ok(result)
}

/// `_expand`: the children of every hypothesis for one detection (eq. 1 with eqs.
/// 4-8), merged and pruned (eq. 3, n_hyp,max).
fn expand(
    hypotheses: Vec<Hypothesis>,
    option: &DetectionOptions,
    table: &mut Table,
    settings: &Settings,
) -> KernelResult<Vec<Hypothesis>> {
    let mht = settings.mht;
    let label = option.label;
    // eq. (4): an object counts under any version a hypothesis holds of it
    let mut presence: Vec<Presence> = Vec::with_capacity(option.presence.len());
    for p in &option.presence {
        presence.push(*p);
        for &version in table.derived.get(&p.key).map_or(&[][..], Vec::as_slice) {
            presence.push(Presence { key: version, ..*p });
        }
    }
    presence.sort_by_key(|p| p.key);
    // objects that gave their label up earlier in the scan may still take this one
    let mut copies: Vec<(u64, Existing)> = option
        .existing
        .iter()
        .filter_map(|e| table.copies.get(&e.old_key).map(|&copy| (copy, *e)))
        .collect();
    copies.sort_by_key(|(copy, _)| *copy);
    let log_clutter = option.log_clutter;
    let log_or_clutter = log_add(log_clutter, option.new_log); // the usual "new or clutter"
    let floor = update_floor(&hypotheses, option, !copies.is_empty(), settings);
    let mut born_at: KeyMap<u64, u64> = KeyMap::default(); // birth weight -> version (mht)
                                                           // each hypothesis's children: clutter or new, and each update it allows
    let mut children =
        Merged::with_capacity((hypotheses.len() * (2 + option.existing.len())).min(64));
    for h in &hypotheses {
        let keys = &h.keys;
        let (mut birth_rate, mut birth_log) = (option.new_rate, option.new_log);
        for p in &presence {
            if p.log_num > birth_log && holds(keys, p.key) {
                (birth_rate, birth_log) = (p.rate, p.log_num);
            }
        }
        let mut log_norm = h.log_weight;
        if !mht {
            // paper 002 eqs. (5)-(7): F sums the frequencies open to this detection;
            // objects that took a detection of this scan cannot take another
            let mut taken = 0.0;
            for &k in keys.iter().filter(|k| table.fresh.contains(k)) {
                taken += table.rate(k)?;
            }
            log_norm -= checked_ln(option.clutter_rate + birth_rate + (h.rate - taken))?;
        }
        let labelled = label.is_some_and(|l| keys.iter().any(|&k| table.holds_label(k, l)));
        if mht {
            // one child "new object or clutter": an object with existence
            // lambda_b / (lambda_b + lambda_c), weight lambda_b + lambda_c
            let mut log_unassigned = if birth_log == option.new_log {
                log_or_clutter
            } else {
                log_add(log_clutter, birth_log)
            };
            if labelled {
                log_unassigned += settings.log_label_error;
            }
            if birth_log > f64::NEG_INFINITY {
                let weight_key = (birth_log + 0.0).to_bits();
                let born = match born_at.get(&weight_key) {
                    Some(&born) => born,
                    None => {
                        let born = birth(option, birth_log, table)?;
                        born_at.insert(weight_key, born);
                        born
                    }
                };
                let mut child = with_key(keys, born);
                if let (true, Some(l)) = (labelled, label) {
                    child = give_label(child, born, l, table)?;
                }
                children.add(
                    child,
                    log_norm + log_unassigned,
                    h.rate + option.new_track_rate,
                );
            } else if log_unassigned > f64::NEG_INFINITY {
                children.add(keys.clone(), log_norm + log_unassigned, h.rate);
            }
        } else {
            if log_clutter > f64::NEG_INFINITY {
                children.add(keys.clone(), log_norm + log_clutter, h.rate);
            }
            if birth_log > f64::NEG_INFINITY {
                let mut child = with_key(keys, option.new_key);
                if let (true, Some(l)) = (labelled, label) {
                    child = give_label(child, option.new_key, l, table)?;
                }
                children.add(child, log_norm + birth_log, h.rate + option.new_track_rate);
            }
        }
        for e in option.existing.iter().filter(|e| holds(keys, e.old_key)) {
            let mut log_num = e.log_num;
            if let (true, true, Some(l)) = (mht, labelled, label) {
                if !table.holds_label(e.old_key, l) && table.get(e.old_key)?.label.is_none() {
                    // an unlabelled object takes the label from its holder: another
                    // explanation than the holder, it pays the label error too
                    log_num += settings.log_label_error;
                }
            }
            if log_norm + log_num < floor {
                continue; // pruned by eq. (3) whatever else is built: no set made
            }
            let mut child = replaced(keys, e.old_key, e.updated);
            if let (true, Some(l)) = (labelled, label) {
                child = give_label(child, e.updated, l, table)?;
            }
            children.add(child, log_norm + log_num, h.rate + e.rate_change);
        }
        for (copy, e) in copies.iter().filter(|(copy, _)| holds(keys, *copy)) {
            let holder = match label {
                Some(_) => e.updated,
                None => table.unlabeled(e.updated)?,
            };
            let mut child = replaced(keys, *copy, holder);
            if let Some(l) = label {
                child = give_label(child, holder, l, table)?;
            }
            children.add(child, log_norm + e.log_num, h.rate + e.rate_change);
        }
    }
    if children.is_empty() {
        // nothing can explain it: a knowledge base with no clutter or births
        return Ok(hypotheses);
    }
    prune(children, settings.ratio, settings.max_hypotheses)
}

/// The expansion of one scan: every option in turn, from the given clusters to the
/// scan's clusters (the loop of `process_scan`).
pub fn expand_scan(scan: Scan) -> KernelResult<Expanded> {
    let settings = scan.settings;
    let given: BTreeSet<usize> = scan.clusters.iter().map(|(id, _)| *id).collect();
    if given.iter().any(|&id| id >= scan.cluster_count) {
        return Err(KernelError::Shape(format!(
            "clusters: expected indices below cluster_count = {}",
            scan.cluster_count
        )));
    }
    let mut table = Table::new(scan.tracks, scan.first_new, scan.next_key);
    let mut book = Book::new(scan.clusters, scan.cluster_count);
    for option in &scan.options {
        let option = match option {
            ScanOption::Settled { old_key, updated } => {
                // what `certain_update` would give
                table.add(*updated, Some(*old_key), true)?;
                let owners = book.owners([*old_key]);
                book.take(&owners);
                book.put(vec![Cluster::certain(*updated, table.rate(*updated)?)]);
                continue;
            }
            ScanOption::Done(versions) => {
                for e in versions {
                    table.add(e.updated, Some(e.old_key), true)?;
                }
                continue;
            }
            ScanOption::Detection(option) => option,
        };
        if !settings.mht {
            table.add(option.new_key, None, true)?;
        }
        for e in &option.existing {
            table.add(e.updated, Some(e.old_key), true)?;
        }
        let touched = if settings.mht {
            let mut involved: Vec<u64> = option.existing.iter().map(|e| e.old_key).collect();
            involved.extend(option.presence.iter().map(|p| p.key));
            if let Some(holders) = option.label.and_then(|l| table.by_label.get(&l)) {
                involved.extend(holders.iter().copied());
            }
            book.owners(involved)
        } else {
            book.ids()
        };
        if let Some(certain) = certain_update(&book, &touched, option, &table, &settings)? {
            book.take(&touched);
            book.put(vec![certain]);
            continue;
        }
        let merged = product(book.take(&touched), settings.ratio, settings.max_hypotheses)?;
        let expanded = expand(merged, option, &mut table, &settings)?;
        book.put(split(expanded, &table, settings.mht)?);
    }
    let untouched = given
        .into_iter()
        .filter(|id| book.clusters.contains_key(id))
        .collect();
    let (mut untouched_clusters, mut clusters) = (Vec::new(), Vec::new());
    for (id, cluster) in book.clusters {
        if id < scan.cluster_count {
            untouched_clusters.push(cluster);
        } else {
            clusters.push(cluster);
        }
    }
    Ok(Expanded {
        untouched,
        untouched_clusters,
        clusters,
        ops: table.ops,
        next_key: table.next_key,
    })
}

/// A scan's versions as they cross the boundary: key, rate (f_existing, Hz) and label of
/// every version the given clusters hold and the options name.
#[derive(Debug, Clone, Default)]
pub struct TrackArrays {
    pub keys: Vec<u64>,
    pub rates: Vec<f64>,
    pub labels: Vec<Option<String>>,
}

/// The given clusters: per cluster its index and number of hypotheses; per hypothesis
/// its number of keys, log weight and rate; the keys one hypothesis after the other.
#[derive(Debug, Clone, Default)]
pub struct ClusterArrays {
    pub ids: Vec<usize>,
    pub sizes: Vec<usize>,
    pub hypothesis_sizes: Vec<usize>,
    pub keys: Vec<u64>,
    pub log_weights: Vec<f64>,
    pub rates: Vec<f64>,
}

/// The options, in the scan's order: per option its kind (`0` detection options, `1`
/// settled, `2` done: its versions in the existing entries), its detection's label,
/// two keys (settled: old, updated; options: the new object's, unused) and five values
/// (options: clutter rate, log clutter, the new object's rate, base f_new, its log
/// numerator; others: unused).
#[derive(Debug, Clone, Default)]
pub struct OptionArrays {
    pub kinds: Vec<u8>,
    pub labels: Vec<Option<String>>,
    pub keys: Vec<u64>,
    pub values: Vec<f64>,
}

/// Entries of the options (presence: per entry its key, then rate and log numerator;
/// existing: its old and updated keys, then log numerator and rate change): per option
/// its number of entries, then the entries' keys and values one after the other.
#[derive(Debug, Clone, Default)]
pub struct EntryArrays {
    pub counts: Vec<usize>,
    pub keys: Vec<u64>,
    pub values: Vec<f64>,
}

impl EntryArrays {
    /// Each option's keys (`keys_per_entry` per entry) and values (two per entry),
    /// every length checked.
    fn per_option(
        &self,
        name: &str,
        options: usize,
        keys_per_entry: usize,
    ) -> KernelResult<Vec<(&[u64], &[f64])>> {
        length(&format!("{name}_counts"), self.counts.len(), options)?;
        let widths: Vec<usize> = self.counts.iter().map(|n| keys_per_entry * n).collect();
        let keys = runs(&format!("{name}_keys"), &self.keys, &widths)?;
        let widths: Vec<usize> = self.counts.iter().map(|n| 2 * n).collect();
        let values = runs(&format!("{name}_values"), &self.values, &widths)?;
        Ok(keys.into_iter().zip(values).collect())
    }
}

/// A scan as flat arrays, as it crosses the boundary (`semwm/mhf/rust_expansion.py`
/// packs it): no object per hypothesis or per option.
#[derive(Debug, Clone, Default)]
pub struct ScanArrays {
    /// `(first_new, next_key, cluster_count)`.
    pub counters: (u64, u64, usize),
    pub tracks: TrackArrays,
    pub clusters: ClusterArrays,
    pub options: OptionArrays,
    pub presence: EntryArrays,
    pub existing: EntryArrays,
}

fn length(name: &str, got: usize, expected: usize) -> KernelResult<()> {
    if got == expected {
        Ok(())
    } else {
        Err(KernelError::Shape(format!(
            "{name}: expected {expected} values, got {got}"
        )))
    }
}

/// Each distinct label as a small id (labels are only compared).
#[derive(Default)]
struct Labels(KeyMap<String, u32>);

impl Labels {
    fn id(&mut self, label: Option<String>) -> Option<u32> {
        let label = label?;
        let next = u32::try_from(self.0.len()).unwrap_or(u32::MAX);
        Some(*self.0.entry(label).or_insert(next))
    }
}

/// Splits `items` into consecutive runs of `counts[i]` items.
fn runs<'a, T>(name: &str, items: &'a [T], counts: &[usize]) -> KernelResult<Vec<&'a [T]>> {
    length(name, items.len(), counts.iter().sum())?;
    let mut at = 0;
    Ok(counts
        .iter()
        .map(|&n| {
            let run = &items[at..at + n];
            at += n;
            run
        })
        .collect())
}

impl ScanArrays {
    /// The scan, every length checked (`ValueError` naming the argument).
    pub fn into_scan(self, settings: Settings) -> KernelResult<Scan> {
        let ScanArrays {
            counters,
            tracks: versions,
            clusters: given,
            options: given_options,
            presence,
            existing,
        } = self;
        let n_tracks = versions.keys.len();
        length("track_rates", versions.rates.len(), n_tracks)?;
        length("track_labels", versions.labels.len(), n_tracks)?;
        let mut labels = Labels::default();
        let mut tracks = KeyMap::with_capacity_and_hasher(n_tracks, Default::default());
        for ((key, rate), label) in versions
            .keys
            .into_iter()
            .zip(versions.rates)
            .zip(versions.labels)
        {
            let label = labels.id(label);
            tracks.insert(key, TrackInfo { rate, label });
        }
        length("cluster_sizes", given.sizes.len(), given.ids.len())?;
        let n_hypotheses: usize = given.sizes.iter().sum();
        length(
            "hypothesis_sizes",
            given.hypothesis_sizes.len(),
            n_hypotheses,
        )?;
        length("log_weights", given.log_weights.len(), n_hypotheses)?;
        length("rates", given.rates.len(), n_hypotheses)?;
        let keys = runs("hypothesis_keys", &given.keys, &given.hypothesis_sizes)?;
        let mut hypotheses = keys.into_iter().enumerate().map(|(i, keys)| {
            let mut keys = keys.to_vec();
            keys.sort_unstable();
            Hypothesis {
                log_weight: given.log_weights[i],
                keys,
                rate: given.rates[i],
            }
        });
        let clusters = given
            .ids
            .iter()
            .zip(&given.sizes)
            .map(|(&id, &size)| {
                let cluster = Cluster::of(hypotheses.by_ref().take(size).collect());
                (id, Arc::new(cluster))
            })
            .collect();
        let n_options = given_options.kinds.len();
        length("option_labels", given_options.labels.len(), n_options)?;
        length("option_keys", given_options.keys.len(), 2 * n_options)?;
        length("option_values", given_options.values.len(), 5 * n_options)?;
        let presence = presence.per_option("presence", n_options, 1)?;
        let existing = existing.per_option("existing", n_options, 2)?;
        let existing: Vec<Vec<Existing>> = existing
            .into_iter()
            .map(|(keys, values)| {
                let mut entries: Vec<Existing> = keys
                    .chunks_exact(2)
                    .zip(values.chunks_exact(2))
                    .map(|(k, v)| Existing {
                        old_key: k[0],
                        updated: k[1],
                        log_num: v[0],
                        rate_change: v[1],
                    })
                    .collect();
                entries.sort_by_key(|e| e.old_key);
                entries
            })
            .collect();
        let mut options = Vec::with_capacity(n_options);
        let option_labels = given_options.labels.into_iter();
        for (j, (label, existing)) in option_labels.zip(existing).enumerate() {
            let label = labels.id(label);
            let keys = &given_options.keys[2 * j..2 * j + 2];
            let values = &given_options.values[5 * j..5 * j + 5];
            options.push(match given_options.kinds[j] {
                0 => ScanOption::Detection(DetectionOptions {
                    label,
                    clutter_rate: values[0],
                    log_clutter: values[1],
                    new_key: keys[0],
                    new_track_rate: values[2],
                    new_rate: values[3],
                    new_log: values[4],
                    presence: presence[j]
                        .0
                        .iter()
                        .zip(presence[j].1.chunks_exact(2))
                        .map(|(&key, v)| Presence {
                            key,
                            rate: v[0],
                            log_num: v[1],
                        })
                        .collect(),
                    existing,
                }),
                1 => ScanOption::Settled {
                    old_key: keys[0],
                    updated: keys[1],
                },
                2 => ScanOption::Done(existing),
                other => {
                    return Err(KernelError::Shape(format!(
                        "option_kinds: expected 0 (options), 1 (settled) or 2 (done), got {other}"
                    )))
                }
            });
        }
        let (first_new, next_key, cluster_count) = counters;
        Ok(Scan {
            settings,
            tracks,
            first_new,
            next_key,
            clusters,
            cluster_count,
            options,
        })
    }
}

/// The scan's result as flat arrays (the layout of `ScanArrays`' clusters): the given
/// clusters left untouched; per new cluster its number of hypotheses and of keys, its
/// keys; per hypothesis its number of keys, its keys, log weight and rate; per version
/// made its kind (`0` birth, `1` copy), key, source and existence (copies: NaN, the
/// caller copies it); the next key.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ExpandedArrays {
    pub untouched: Vec<usize>,
    pub cluster_sizes: Vec<usize>,
    pub cluster_key_sizes: Vec<usize>,
    pub cluster_keys: Vec<u64>,
    pub hypothesis_sizes: Vec<usize>,
    pub hypothesis_keys: Vec<u64>,
    pub log_weights: Vec<f64>,
    pub rates: Vec<f64>,
    pub op_kinds: Vec<u8>,
    pub op_keys: Vec<u64>,
    pub op_sources: Vec<u64>,
    pub op_existence: Vec<f64>,
    pub next_key: u64,
}

impl From<Expanded> for ExpandedArrays {
    fn from(expanded: Expanded) -> ExpandedArrays {
        let mut out = ExpandedArrays {
            untouched: expanded.untouched,
            next_key: expanded.next_key,
            ..ExpandedArrays::default()
        };
        for cluster in expanded.clusters {
            out.cluster_sizes.push(cluster.hypotheses.len());
            out.cluster_key_sizes.push(cluster.keys.len());
            out.cluster_keys.extend_from_slice(&cluster.keys);
            for h in &cluster.hypotheses {
                out.hypothesis_sizes.push(h.keys.len());
                out.hypothesis_keys.extend_from_slice(&h.keys);
                out.log_weights.push(h.log_weight);
                out.rates.push(h.rate);
            }
        }
        for op in expanded.ops {
            let (kind, key, from, existence) = match op {
                Op::Birth {
                    key,
                    from,
                    existence,
                } => (0, key, from, existence),
                Op::Copy { key, from } => (1, key, from, f64::NAN),
            };
            out.op_kinds.push(kind);
            out.op_keys.push(key);
            out.op_sources.push(from);
            out.op_existence.push(existence);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings(mht: bool) -> Settings {
        Settings {
            ratio: 1e-3,
            max_hypotheses: 100,
            mht,
            log_label_error: 0.01_f64.ln(),
        }
    }

    fn h(log_weight: f64, keys: &[u64], rate: f64) -> Hypothesis {
        Hypothesis {
            log_weight,
            keys: keys.to_vec(),
            rate,
        }
    }

    fn info(rate: f64) -> TrackInfo {
        TrackInfo { rate, label: None }
    }

    fn detection(new_key: u64, existing: Vec<Existing>) -> DetectionOptions {
        DetectionOptions {
            label: None,
            clutter_rate: 1.0,
            log_clutter: -3.0,
            new_key,
            new_track_rate: 2.0,
            new_rate: 0.5,
            new_log: -4.0,
            presence: Vec::new(),
            existing,
        }
    }

    #[test]
    fn product_of_two_clusters_multiplies_and_normalises() {
        let a = vec![h(0.5_f64.ln(), &[1], 1.0), h(0.5_f64.ln(), &[], 0.0)];
        let b = vec![h(0.0, &[2], 2.0)];
        let joined = product(vec![a, b], 0.0, 10).unwrap();
        assert_eq!(joined.len(), 2);
        assert_eq!(joined[0].keys, vec![1, 2]);
        assert_eq!(joined[1].keys, vec![2]);
        assert_eq!(joined[0].rate, 3.0);
        assert!((joined[0].log_weight - 0.5_f64.ln()).abs() < 1e-15);
        let empty = product(Vec::new(), 0.0, 10).unwrap();
        assert_eq!(empty, vec![h(0.0, &[], 0.0)]);
    }

    /// Object 1 alone and certain (cluster 0); 5 would be its update, 6 the new object.
    fn one_object(mht: bool, options: Vec<ScanOption>) -> Scan {
        Scan {
            settings: settings(mht),
            tracks: KeyMap::from_iter([(1, info(1.0)), (5, info(1.5)), (6, info(2.0))]),
            first_new: 5,
            next_key: 7,
            clusters: vec![(0, Cluster::certain(1, 1.0).into())],
            cluster_count: 1,
            options,
        }
    }

    /// Object 1 updated to version 5 with log numerator `log_num`.
    fn update_of_one(log_num: f64) -> Vec<Existing> {
        vec![Existing {
            old_key: 1,
            updated: 5,
            log_num,
            rate_change: 0.5,
        }]
    }

    #[test]
    fn a_certain_update_replaces_the_object() {
        let option = DetectionOptions {
            log_clutter: -20.0,
            new_log: -21.0,
            ..detection(6, update_of_one(0.0))
        };
        let expanded = expand_scan(one_object(true, vec![ScanOption::Detection(option)])).unwrap();
        assert!(expanded.untouched.is_empty() && expanded.ops.is_empty());
        assert_eq!(expanded.clusters, vec![Arc::new(Cluster::certain(5, 1.5))]);
        assert_eq!(expanded.next_key, 7);
    }

    #[test]
    fn an_uncertain_detection_starts_an_object_with_its_existence() {
        let option = ScanOption::Detection(detection(6, update_of_one(-3.5)));
        let expanded = expand_scan(one_object(true, vec![option])).unwrap();
        let existence = (-4.0 - log_add(-3.0, -4.0)).exp();
        assert_eq!(
            expanded.ops,
            vec![Op::Birth {
                key: 6,
                from: 6,
                existence
            }]
        );
        assert_eq!(expanded.clusters.len(), 1);
        let cluster = &expanded.clusters[0];
        assert_eq!(cluster.keys, vec![1, 5, 6]);
        // "new or clutter" (weight log_add(-3, -4)) against the update (-3.5)
        let unassigned = log_add(-3.0, -4.0);
        let total = log_add(unassigned, -3.5);
        assert_eq!(cluster.hypotheses[0].keys, vec![1, 6]);
        assert!((cluster.hypotheses[0].log_weight - (unassigned - total)).abs() < 1e-15);
        assert_eq!(cluster.hypotheses[1].keys, vec![5]);
        assert_eq!(cluster.hypotheses[0].rate, 3.0);
    }

    #[test]
    fn a_labelled_detection_takes_the_label_from_its_holder() {
        let labelled = TrackInfo {
            rate: 1.0,
            label: Some(0),
        };
        let tracks =
            KeyMap::from_iter([(1, labelled), (2, info(1.0)), (5, labelled), (6, labelled)]);
        let mut option = detection(
            6,
            vec![Existing {
                old_key: 2,
                updated: 5,
                log_num: -1.0,
                rate_change: 0.0,
            }],
        );
        option.label = Some(0);
        let both = vec![h(0.0, &[1, 2], 2.0)];
        let scan = Scan {
            settings: settings(true),
            tracks,
            first_new: 5,
            next_key: 7,
            clusters: vec![(0, Cluster::of(both).into())],
            cluster_count: 1,
            options: vec![ScanOption::Detection(option)],
        };
        let expanded = expand_scan(scan).unwrap();
        // whichever object takes the label (object 2, updated to 5, or the new object 6),
        // its holder 1 gives it up: its copy 7 without label, then certain and split off
        assert_eq!(expanded.ops[1], Op::Copy { key: 7, from: 1 });
        let sets: Vec<Vec<Vec<u64>>> = expanded
            .clusters
            .iter()
            .map(|c| c.hypotheses.iter().map(|h| h.keys.clone()).collect())
            .collect();
        assert_eq!(sets, vec![vec![vec![7]], vec![vec![5], vec![2, 6]]]);
    }

    #[test]
    fn paper_keeps_one_global_cluster_and_pays_f_per_parent() {
        let mut option = detection(6, Vec::new());
        option.log_clutter = 1.0_f64.ln();
        option.new_log = 0.5_f64.ln();
        let scan = one_object(false, vec![ScanOption::Detection(option)]);
        let expanded = expand_scan(scan).unwrap();
        assert_eq!(expanded.clusters.len(), 1);
        let hypotheses = &expanded.clusters[0].hypotheses;
        assert_eq!(hypotheses[0].keys, vec![1]); // clutter: 1 / (1 + 0.5 + 1)
        assert_eq!(hypotheses[1].keys, vec![1, 6]);
        assert!((hypotheses[0].log_weight.exp() - 2.0 / 3.0).abs() < 1e-15);
    }

    #[test]
    fn a_version_not_given_is_an_error_not_a_panic() {
        let settled = ScanOption::Settled {
            old_key: 1,
            updated: 5,
        };
        let mut scan = one_object(true, vec![settled]);
        scan.tracks.clear();
        assert!(matches!(expand_scan(scan), Err(KernelError::Value(_))));
    }
}
