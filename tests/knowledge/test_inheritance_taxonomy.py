"""Inheritance through is-a and the taxonomy (paper 002 Section IV, Fig. 1, eq. (8))."""

from __future__ import annotations

import pytest

from semwm.knowledge import Knowledge, Taxonomy, load_knowledge
from semwm.knowledge.loader import knowledge_from_text
from semwm.knowledge.shipped import shipped_knowledge_path

FAMILY = """\
world: {dimension: 2}
classes:
  - name: Animal
    detection_frequency: 1.0
    new_frequency: 0.2
    filter:
      type: kalman
      model: {motion_model: first_order, system_noise: [[1, 0], [0, 1]]}
    measurement_noise: [[0.04, 0], [0, 0.04]]
    max_position_variance: 2.0
    category: foreign_controlled
  - name: Cat
    is_a: [Animal]
    detection_frequency: 3.0
    measurement_noise: [[0.01, 0], [0, 0.01]]
  - name: Kitten
    is_a: [Cat]
    max_time_without_update: 5.0
detectors:
  - {name: eye, clutter_frequency: 0.1, range: 8.0}
"""


@pytest.fixture(scope="module")
def family() -> Knowledge:
    return knowledge_from_text(FAMILY, "yaml", "family.yaml")


@pytest.fixture(scope="module")
def sim1() -> Knowledge:
    return load_knowledge(shipped_knowledge_path("sim1.xml"))


def taxonomy_of(knowledge: Knowledge) -> Taxonomy:
    return Taxonomy({name: c.parents for name, c in knowledge.classes.items()})


def test_a_subclass_inherits_everything_it_does_not_write(sim1: Knowledge) -> None:
    can = sim1.classes["Can"].model_dump(exclude={"name", "parents", "ancestors"})
    for name in ("CokeCan", "BeerCan"):
        assert sim1.classes[name].model_dump(exclude={"name", "parents", "ancestors"}) == can


def test_a_subclass_overrides_what_it_writes(family: Knowledge) -> None:
    animal, cat = family.classes["Animal"], family.classes["Cat"]
    assert cat.detection_frequency == 3.0 != animal.detection_frequency
    assert cat.measurement_noise == ((0.01, 0.0), (0.0, 0.01))
    assert cat.new_frequency == animal.new_frequency == 0.2
    assert cat.filter == animal.filter
    assert cat.category == "foreign_controlled"


def test_inheritance_goes_through_every_generation(family: Knowledge) -> None:
    kitten = family.classes["Kitten"]
    assert kitten.ancestors == ("Cat", "Animal")
    assert kitten.detection_frequency == 3.0  # from Cat, the nearest ancestor writing it
    assert kitten.max_position_variance == 2.0  # from Animal
    assert kitten.max_time_without_update == 5.0  # its own
    assert family.classes["Cat"].max_time_without_update is None


def test_initial_covariance_defaults_to_the_measurement_noise(family: Knowledge) -> None:
    cat = family.classes["Cat"]
    assert cat.initial_covariance == cat.measurement_noise


def test_ancestors_and_descendants(sim1: Knowledge) -> None:
    taxonomy = taxonomy_of(sim1)
    assert taxonomy.ancestors("CokeCan") == {"Can"}
    assert taxonomy.ancestors("Can") == frozenset()
    assert taxonomy.descendants("Can") == {"CokeCan", "BeerCan"}
    assert taxonomy.descendants("Cup") == frozenset()


@pytest.mark.parametrize(
    ("object_class", "detection_class", "likelihood"),
    [
        ("CokeCan", "Can", 1.0),  # the detection names a superclass
        ("Can", "BeerCan", 1.0),  # the detection names a subclass
        ("Cup", "Cup", 1.0),
        ("CokeCan", "BeerCan", 0.0),  # siblings are not compatible
        ("Cup", "Can", 0.0),
        ("Table", "CokeCan", 0.0),
    ],
)
def test_class_likelihood_of_eq_8(
    sim1: Knowledge, object_class: str, detection_class: str, likelihood: float
) -> None:
    assert taxonomy_of(sim1).class_likelihood(object_class, detection_class) == likelihood


def test_most_specific_and_covers(sim1: Knowledge) -> None:
    taxonomy = taxonomy_of(sim1)
    assert taxonomy.most_specific("Can", "CokeCan") == "CokeCan"
    assert taxonomy.most_specific("BeerCan", "Can") == "BeerCan"
    with pytest.raises(ValueError, match="not compatible"):
        taxonomy.most_specific("CokeCan", "Cup")
    assert taxonomy.covers("Can") == {"Can", "CokeCan", "BeerCan"}
    assert taxonomy.covers("CokeCan") == {"CokeCan"}
