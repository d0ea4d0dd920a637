"""The named parameter sets: validation, lookup, serialization, the shipped ones."""

from __future__ import annotations

import dataclasses

import pytest

from worker.engine.presets import (
    COMPARISON_FIELDS,
    DEFAULT_PRESET,
    MODALITIES,
    PRESETS,
    SIZE,
    Preset,
    get_preset,
    with_units,
)


def test_inconsistent_presets_are_refused():
    with pytest.raises(ValueError, match="more slices than diffusion times"):
        Preset(name="x", version=1, ddt_core_shape=(20, 20, 6))
    with pytest.raises(ValueError, match="one slice per time"):
        Preset(name="x", version=1, ddt_core_shape=(20, 20, 4), ddt_mix_times=False)
    with pytest.raises(ValueError, match="spectrum_size must be below n_eigenpairs"):
        Preset(name="x", version=1, spectrum_size=150, n_eigenpairs=150)
    with pytest.raises(ValueError, match=r"unknown modalities \['colour'\]"):
        Preset(name="x", version=1, fused_modalities=("gdm", "colour"))
    with pytest.raises(ValueError, match="gdm_samples needs the surface measure"):
        Preset(name="x", version=1, gdm_samples=500)  # the paper's vertex matrices
    with pytest.raises(ValueError, match="at least gdm_singular_values samples"):
        Preset(name="x", version=1, measure="surface", gdm_samples=10)
    with pytest.raises(ValueError, match="averaged mass needs the surface measure"):
        Preset(name="x", version=1, ddt_mass="averaged")
    with pytest.raises(ValueError, match="at least one query scale per step"):
        Preset(name="x", version=1, parts_scale_steps=0)
    with pytest.raises(ValueError, match="parts_extra_scales: a number of steps"):
        Preset(name="x", version=1, parts_extra_scales=-1)


def test_unknown_preset_names_the_known_ones():
    with pytest.raises(KeyError) as error:
        get_preset("smeets2011")
    message = error.value.args[0]
    assert message.startswith("unknown preset 'smeets2011'; known presets: ")
    assert message.endswith(", ".join(sorted(PRESETS)))


def test_to_dict_round_trips():
    preset = Preset(
        name="x", version=3, n_vertices=1000, fusion_weights={"gdm": 0.5}, dissimilarity="D1"
    )
    data = preset.to_dict()
    assert data["fusion_weights"] == {"gdm": 0.5} and data["ddt_core_shape"] == (20, 20, 5)
    assert Preset(**data) == preset
    assert {f.name for f in dataclasses.fields(Preset)} == set(data)


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_every_shipped_preset_is_valid(name):
    preset = get_preset(name)
    assert preset.name == name and preset.version >= 1
    assert preset.dissimilarity in ("D1", "D2") and preset.fusion in ("sum", "product")
    assert set(preset.fused_modalities) <= set(MODALITIES)
    assert Preset(**preset.to_dict()) == preset  # passes __post_init__'s checks again
    assert preset.weight("gdm") == preset.fusion_weights.get("gdm", 1.0)


def test_the_paper_presets_keep_the_papers_parameters():
    shrec, tosca = get_preset("smeets2010-shrec"), get_preset("smeets2010-tosca")
    for preset in (shrec, tosca):
        assert (preset.gdm_singular_values, preset.ddt_core_shape) == (19, (20, 20, 5))
        assert preset.diffusion_times == (100.0, 200.0, 400.0, 800.0, 1500.0)
        assert (preset.measure, preset.ddt_elements, preset.heat_time_factor) == (
            "vertices",
            "core",
            1.0,
        )
    assert (shrec.n_vertices, shrec.dissimilarity, shrec.fusion) == (2500, "D2", "product")
    assert (tosca.n_vertices, tosca.dissimilarity, tosca.fusion) == (3000, "D1", "sum")
    # Sec. 4.1: "the objects have already the same scale"; sec. 4.2 divides by the sums.
    assert (tosca.normalize_scale, shrec.normalize_scale) == (False, True)


def test_the_default_fuses_all_three_modalities_by_a_weighted_product():
    preset = get_preset(DEFAULT_PRESET)
    assert preset.measure == "surface" and preset.fusion == "product"
    assert preset.fused_modalities == ("gdm", "ddt", "spectrum")
    assert set(preset.fusion_weights) == {*MODALITIES, SIZE}  # the size: metric units only


def test_modality_sizes_follow_the_ddt_elements():
    core = Preset(name="x", version=1)
    diagonal = Preset(name="x", version=1, ddt_elements="diagonal")
    assert core.modality_sizes() == {"gdm": 19, "ddt": 2000, "spectrum": 50}
    assert diagonal.modality_sizes()["ddt"] == 100
    values = Preset(name="x", version=1, ddt_elements="slice_values", ddt_mix_times=False)
    assert values.modality_sizes()["ddt"] == 100
    with pytest.raises(ValueError, match="each time's own"):
        Preset(name="x", version=1, ddt_elements="slice_values")


def test_descriptor_fields_leave_out_how_descriptors_are_compared():
    preset = get_preset(DEFAULT_PRESET)
    reweighted = dataclasses.replace(preset, fusion_weights={"ddt": 1.0}, dissimilarity="D2")
    assert reweighted.descriptor_fields() == preset.descriptor_fields()
    assert "heat_time_factor" in preset.descriptor_fields()
    assert "fusion_weights" not in preset.descriptor_fields()


def test_units_say_how_a_collection_is_compared_not_how_shapes_are_described():
    preset = get_preset(DEFAULT_PRESET)
    metric = with_units(preset, "metric")
    assert metric.units == "metric" and with_units(metric, "any") == preset
    assert metric.scored_modalities == (*preset.fused_modalities, SIZE)
    assert metric.modality_sizes() == {**preset.modality_sizes(), SIZE: 1}
    assert metric.comparison(SIZE) == "D1 >= 0.02" and metric.comparison("ddt") == "D1"
    assert "size_tolerance" in COMPARISON_FIELDS
    with pytest.raises(ValueError, match="size_tolerance is a D1 value"):
        Preset(name="x", version=1, size_tolerance=-0.1)
    assert "units" in COMPARISON_FIELDS and metric.descriptor_fields() == preset.descriptor_fields()
    assert Preset(**metric.to_dict()) == metric
    with pytest.raises(ValueError, match="unknown units 'imperial'"):
        with_units(preset, "imperial")
    with pytest.raises(ValueError, match="weighs the size"):
        with_units(Preset(name="x", version=1), "metric")
    with pytest.raises(ValueError, match=r"unknown modalities \['colour'\] in fusion_weights"):
        Preset(name="x", version=1, fusion_weights={"colour": 1.0})


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_every_shipped_preset_can_serve_a_metric_collection(name):
    preset = get_preset(name)
    assert preset.units == "any" and preset.weight(SIZE) > 0.0
    assert with_units(preset, "metric").scored_modalities[-1] == SIZE


def test_only_the_sec_4_1_preset_keeps_the_scale():
    assert [p.name for p in PRESETS.values() if not p.normalize_scale] == ["smeets2010-tosca"]
    with pytest.raises(ValueError, match="sec. 4.1's, on the vertices measure"):
        Preset(name="x", version=1, measure="surface", normalize_scale=False)
