import pytest

from avrisk.assembly.parts import camera_from_spec
from avrisk.render import DEFAULT_VEHICLE_HEIGHT, CameraModel
from avrisk.scenario import ScenarioSpecError, load_spec, spec_from_dict
from avrisk.scenario.sensors import CameraSpec


def test_highway_vision_is_highway_default_with_the_vision_ego_and_a_camera():
    vision, default = load_spec("highway_vision"), load_spec("highway_default")
    assert vision.ego.policy == "vision_pilotnet"
    assert vision.camera == CameraSpec()
    assert vision.vehicles[5].height == 3.5
    same = ("road", "initial_conditions", "drivers", "simulation", "safety")
    for section in same:
        assert getattr(vision, section) == getattr(default, section)
    strip = [v.model_copy(update={"height": None}) for v in vision.vehicles]
    assert tuple(strip) == default.vehicles


def test_a_spec_without_camera_or_heights_dumps_as_before():
    dumped = load_spec("highway_default").model_dump(mode="json")
    assert "camera" not in dumped
    assert all("height" not in v for v in dumped["vehicles"])


def test_the_camera_spec_defaults_match_the_camera_model_and_pilotnet():
    assert CameraModel(**CameraSpec().model_dump()) == CameraModel()
    assert (CameraSpec().width, CameraSpec().height) == (200, 66)


def test_the_camera_gets_the_slots_heights_and_the_default_for_the_others():
    camera = camera_from_spec(load_spec("highway_vision"))
    heights = [DEFAULT_VEHICLE_HEIGHT] * 5 + [3.5]
    assert camera._heights.tolist() == pytest.approx(heights)


@pytest.mark.parametrize(
    ("camera", "match"),
    [
        ({"pitch": 60.0}, "camera.pitch"),
        ({"hfov": 0.0}, "camera.hfov"),
        ({"width": 0}, "camera.width"),
        ({"zoom": 2.0}, "camera.zoom"),
    ],
)
def test_a_bad_camera_is_refused_naming_the_field(camera, match):
    data = load_spec("highway_vision").model_dump(mode="json")
    data["camera"] = camera
    with pytest.raises(ScenarioSpecError, match=match):
        spec_from_dict(data)
