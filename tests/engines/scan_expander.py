"""The expansion algebra of one scan in the core (``core/src/mhf/expansion.rs``), driven
on a scan's options: the parity harness of ``test_expansion.py``, which holds it to
step 5 of :mod:`semwm.mhf.filter` (``_product``, ``_expand``, ``_split``,
``_certain_update``, merging and pruning). The Rust engine's whole scan
(``core/src/mhf/filter.rs``) calls the same algebra on its own state; this module hands
it a scan's clusters and options as flat lists instead, so that random cases reach it
directly.

- in: the clusters the scan can touch (those holding an object some detection may
  update, whose presence makes a birth likelier, or that holds a detection's label);
  every version they hold and every version the options name (key, rate, label); the
  options, in the scan's order;
- out: the given clusters no detection touched, the new clusters, and the versions the
  expansion made (births, copies that gave a label up) in the order their keys were
  given, which :class:`ScanExpander` then makes in the scan's track table as the Python
  methods would have.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from semwm.filters.engine import EngineUnavailable
from semwm.mhf.association import DetectionOptions, SettledUpdate
from semwm.mhf.state import Cluster, Hypothesis, Track

if TYPE_CHECKING:
    from semwm.mhf.filter import _ClusterBook, _TrackTable

try:
    from semwm import _core
except ImportError:  # not built: ScanExpander raises EngineUnavailable
    _core = None  # type: ignore[assignment]

_OPTIONS, _SETTLED, _DONE = 0, 1, 2
_UNUSED = (0.0, 0.0, 0.0, 0.0, 0.0)
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
        book: _ClusterBook,
        options: Sequence[DetectionOptions | SettledUpdate],
        start: int,
        table: _TrackTable,
    ) -> None:
        """The scan's options from ``start`` on, as ``MultipleHypothesisFilter._expand_scan``
        expands them: ``book`` ends holding the clusters the Python methods would leave
        in it, ``table`` the versions they would make. The options before ``start``
        were settled or certain updates, already in ``book`` and ``table``; so are the
        versions of option ``start``."""
        factorised = self._factorised
        add = table.add
        by_label = table.by_label
        versions: list[Track] = []  # every version the options name
        kinds: list[int] = []
        labels: list[str | None] = []
        option_keys: list[int] = []
        values: list[float] = []
        presence_counts: list[int] = []
        presence_keys: list[int] = []
        presence_values: list[float] = []
        existing_counts: list[int] = []
        existing_keys: list[int] = []
        existing_values: list[float] = []
        new_tracks: dict[int, Track] = {}
        involved: set[int] = set()  # objects whose clusters the options may touch (mht)
        settled_keys: set[int] = set()
        for position, option in enumerate(options):
            if position < start:  # done: the core only learns the versions it made
                if isinstance(option, SettledUpdate):
                    # nothing reads them: a scan with settled updates has no labels and
                    # no appearance relations (Associator._settled), and they are mht's
                    continue
                pairs = tuple((k, found[0]) for k, found in option.existing.items())
                kinds.append(_DONE)
                labels.append(None)
                option_keys += (0, 0)
                values += _UNUSED
                presence_counts.append(0)
                existing_counts.append(len(pairs))
                for old_key, updated in pairs:
                    versions.append(updated)
                    existing_keys += (old_key, updated.key)
                    existing_values += (0.0, 0.0)
                continue
            later = position > start  # its versions are not in the table yet
            if isinstance(option, SettledUpdate):
                updated = option.updated
                versions.append(updated)
                add(updated, origin=option.old_key, fresh=True)
                settled_keys.add(option.old_key)
                kinds.append(_SETTLED)
                labels.append(None)
                option_keys += (option.old_key, updated.key)
                values += _UNUSED
                presence_counts.append(0)
                existing_counts.append(0)
                continue
            new_track = option.new_track
            new_tracks[new_track.key] = new_track
            versions.append(new_track)
            if later and not factorised:  # paper: the new object is a child of every parent
                add(new_track, fresh=True)
            label = option.measurement.label
            kinds.append(_OPTIONS)
            labels.append(label)
            option_keys += (new_track.key, 0)
            values += (
                option.clutter_rate,
                option.log_clutter,
                new_track.rate,
                option.new_rate,
                option.new_log,
            )
            presence = option.presence
            presence_counts.append(len(presence))
            for key, (rate, log_num) in presence.items():
                presence_keys.append(key)
                presence_values += (rate, log_num)
            existing = option.existing
            existing_counts.append(len(existing))
            for old_key, (updated, log_num, rate_change) in existing.items():
                versions.append(updated)
                if later:
                    add(updated, origin=old_key, fresh=True)
                existing_keys += (old_key, updated.key)
                existing_values += (log_num, rate_change)
            if factorised:
                involved.update(existing)
                involved.update(presence)
                if label is not None:
                    involved.update(by_label.get(label, ()))
        if factorised:
            given_ids = book.owners(involved)
            settled = book.owners(settled_keys) - given_ids
        else:  # paper: every cluster (one global one)
            given_ids, settled = book.ids(), set()
        given = sorted(given_ids)
        clusters = [book.get(i) for i in given]
        tracks = table.tracks
        for cluster in clusters:
            versions.extend([tracks[k] for k in cluster.keys])
        hypotheses = [h for c in clusters for h in c.hypotheses]
        untouched, (sizes, key_sizes, cluster_keys), new, made, next_key = self._core.scan(
            (table._first_new, table.next_key, book.next_id),
            ([t.key for t in versions], [t.rate for t in versions], [t.label for t in versions]),
            (
                given,
                [len(c.hypotheses) for c in clusters],
                [len(h.tracks) for h in hypotheses],
                [k for h in hypotheses for k in h.tracks],
                [h.log_weight for h in hypotheses],
                [h.rate for h in hypotheses],
            ),
            (kinds, labels, option_keys, values),
            (presence_counts, presence_keys, presence_values),
            (existing_counts, existing_keys, existing_values),
        )
        for kind, key, source, existence in zip(*made, strict=True):
            if kind == _BIRTH:
                table.add_birth(new_tracks[source], key, existence)
            else:
                table.copy_unlabeled(source, key)
        table.next_key = next_key
        book.take(settled.union(given).difference(untouched))
        book.put(_clusters(sizes, key_sizes, cluster_keys, *new))


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
        if size == 1 and key_size == 1 and hypothesis_sizes[h] == 1:  # certain: one object
            key = frozenset(keys[at : at + 1])
            result.append(Cluster((Hypothesis(weights[h], key, rates[h]),), key))
            at += 1
            h += 1
            key_at += 1
            continue
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
