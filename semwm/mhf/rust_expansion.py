"""The Rust engine's expansion of one scan: step 5 of :mod:`semwm.mhf.filter`
(``MultipleHypothesisFilter._expand_scan``: ``_product``, ``_expand``, ``_split``,
``_certain_update``, merging and pruning) computed by the compiled core
(``core/src/expansion.rs``, ``core/src/hypotheses.rs``) in one call per scan.

The Python methods are the specification (``tests/engines/`` holds both to the same
hypotheses). What crosses the boundary is flat lists, not an object per hypothesis:

- in: the clusters the scan can touch (those holding an object some detection may
  update, whose presence makes a birth likelier, or that holds a detection's label);
  every version they hold and every version the options name (key, rate, label); the
  options, in the scan's order;
- out: the given clusters no detection touched, the new clusters, and the versions the
  expansion made (births, copies that gave a label up) in the order their keys were
  given, which :class:`ScanExpander` then makes in the scan's track table as the Python
  methods would have.

Importing it is safe without the extension; making a :class:`ScanExpander` then raises
:class:`~semwm.filters.engine.EngineUnavailable`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from semwm.filters.engine import EngineUnavailable
from semwm.mhf.association import DetectionOptions, SettledUpdate
from semwm.mhf.state import Cluster, Hypothesis, Track

if TYPE_CHECKING:
    from semwm.mhf.filter import _TrackTable

try:
    from semwm import _core
except ImportError:  # not built: ScanExpander raises EngineUnavailable
    _core = None  # type: ignore[assignment]

_SETTLED, _OPTIONS = 1, 0
_BIRTH = 0


class ScanExpander:
    """One filter's expansion of a scan in Rust (its eq. (3) ``ratio``, n_hyp,max,
    association model and log label error rate, handed over once)."""

    def __init__(
        self, ratio: float, max_hypotheses: int, model: str, log_label_error: float
    ) -> None:
        if _core is None:
            raise EngineUnavailable("semwm._core is not built (docs/engines.md)")
        self._core = _core.ScanExpansion(ratio, max_hypotheses, model, log_label_error)
        self._factorised = model == "mht"

    def expand(
        self,
        clusters: Sequence[Cluster],
        options: Sequence[DetectionOptions | SettledUpdate],
        table: _TrackTable,
    ) -> tuple[Cluster, ...]:
        """The scan's clusters, as ``MultipleHypothesisFilter._expand_scan`` gives them
        (the same order); the versions made are added to ``table``."""
        given = self._given(clusters, options, table)
        labels: dict[str, int] = {}
        tracks = table.tracks
        track_keys: list[int] = []
        track_rates: list[float] = []
        track_labels: list[int] = []

        def version(track: Track) -> None:
            track_keys.append(track.key)
            track_rates.append(track.rate)
            label = track.label
            track_labels.append(-1 if label is None else labels.setdefault(label, len(labels)))

        sizes: list[int] = []
        hypothesis_sizes: list[int] = []
        keys: list[int] = []
        weights: list[float] = []
        rates: list[float] = []
        for i in given:
            cluster = clusters[i]
            for key in cluster.keys:
                version(tracks[key])
            sizes.append(len(cluster.hypotheses))
            for h in cluster.hypotheses:
                hypothesis_sizes.append(len(h.tracks))
                keys.extend(h.tracks)
                weights.append(h.log_weight)
                rates.append(h.rate)
        kinds: list[int] = []
        option_labels: list[int] = []
        option_keys: list[int] = []
        values: list[float] = []
        presence_counts: list[int] = []
        presence_keys: list[int] = []
        presence_values: list[float] = []
        existing_counts: list[int] = []
        existing_keys: list[int] = []
        existing_values: list[float] = []
        new_tracks: dict[int, Track] = {}
        for option in options:
            if isinstance(option, SettledUpdate):
                version(option.updated)
                table.add(option.updated, origin=option.old_key, fresh=True)
                kinds.append(_SETTLED)
                option_labels.append(-1)
                option_keys += (option.old_key, option.updated.key)
                values += (0.0, 0.0, 0.0, 0.0, 0.0)
                presence_counts.append(0)
                existing_counts.append(0)
                continue
            new_track = option.new_track
            new_tracks[new_track.key] = new_track
            version(new_track)
            if not self._factorised:  # paper: the new object is a child of every parent
                table.add(new_track, fresh=True)
            label = option.measurement.label
            kinds.append(_OPTIONS)
            option_labels.append(-1 if label is None else labels.setdefault(label, len(labels)))
            option_keys += (new_track.key, 0)
            values += (
                option.clutter_rate,
                option.log_clutter,
                new_track.rate,
                option.new_rate,
                option.new_log,
            )
            presence_counts.append(len(option.presence))
            for key, (rate, log_num) in option.presence.items():
                presence_keys.append(key)
                presence_values += (rate, log_num)
            existing_counts.append(len(option.existing))
            for old_key, (updated, log_num, rate_change) in option.existing.items():
                version(updated)
                table.add(updated, origin=old_key, fresh=True)
                existing_keys += (old_key, updated.key)
                existing_values += (log_num, rate_change)
        untouched, (sizes, key_sizes, cluster_keys), hypotheses, made, next_key = self._core.scan(
            (table._first_new, table.next_key, len(clusters)),
            (track_keys, track_rates, track_labels),
            (given, sizes, hypothesis_sizes, keys, weights, rates),
            (kinds, option_labels, option_keys, values),
            (presence_counts, presence_keys, presence_values),
            (existing_counts, existing_keys, existing_values),
        )
        for kind, key, source, existence in zip(*made, strict=True):
            if kind == _BIRTH:
                table.add_birth(new_tracks[source], key, existence)
            else:
                table.copy_unlabeled(source, key)
        table.next_key = next_key
        taken = set(given).difference(untouched)
        kept = [c for i, c in enumerate(clusters) if i not in taken] if taken else list(clusters)
        hypothesis_sizes, new_keys, new_weights, new_rates = hypotheses
        new = _clusters(
            sizes, key_sizes, cluster_keys, hypothesis_sizes, new_keys, new_weights, new_rates
        )
        return (*kept, *new)

    def _given(
        self,
        clusters: Sequence[Cluster],
        options: Sequence[DetectionOptions | SettledUpdate],
        table: _TrackTable,
    ) -> list[int]:
        """The indices of the clusters the scan can touch: under ``paper`` every cluster
        (one global one); under ``mht`` the owners of the objects the options name and
        of the holders of their labels (the clusters ``_ClusterBook.owners`` finds)."""
        if not self._factorised:
            return list(range(len(clusters)))
        involved: set[int] = set()
        for option in options:
            if isinstance(option, SettledUpdate):
                involved.add(option.old_key)
                continue
            involved.update(option.existing)
            involved.update(option.presence)
            label = option.measurement.label
            if label is not None:
                involved.update(table.by_label.get(label, ()))
        if not involved:
            return []
        owner = {k: i for i, c in enumerate(clusters) for k in c.keys}
        return sorted({owner[k] for k in involved if k in owner})


def _clusters(
    sizes: list[int],
    key_sizes: list[int],
    cluster_keys: list[int],
    hypothesis_sizes: list[int],
    keys: list[int],
    weights: list[float],
    rates: list[float],
) -> list[Cluster]:
    """The core's new clusters as :class:`Cluster` values."""
    result: list[Cluster] = []
    at = h = key_at = 0
    for size, key_size in zip(sizes, key_sizes, strict=True):
        hypotheses = []
        for _ in range(size):
            end = at + hypothesis_sizes[h]
            hypotheses.append(Hypothesis(weights[h], frozenset(keys[at:end]), rates[h]))
            at = end
            h += 1
        key_end = key_at + key_size
        result.append(Cluster(tuple(hypotheses), frozenset(cluster_keys[key_at:key_end])))
        key_at = key_end
    return result
