"""One way to name an implementation: gymnast's own by "module:Class", a user's own by
python:MODULE:FACTORY[@ARG] or an installed entry point, plugin:NAME[@ARG]."""

import pytest

from gymnast.policy.load import load_policy
from gymnast.utils.plugins import PluginSpec, entry_point_names, import_named, is_plugin, load_plugin
from gymnast.world_model.base import load_world_model
from tiny_video_wm.gymnast_plugin import TinyVideoWorldModel
from tiny_video_wm.policy import TinyPolicy


def test_a_spec_names_its_factory_and_the_string_it_is_called_with():
    assert PluginSpec.parse("python:my_wm.plugin:load@/ckpt/model") == PluginSpec("my_wm.plugin:load", False, "/ckpt/model")
    assert PluginSpec.parse("plugin:tiny-video") == PluginSpec("tiny-video", True, None)
    assert str(PluginSpec.parse("plugin:tiny-video@w.safetensors")) == "plugin:tiny-video@w.safetensors"
    assert is_plugin("python:a:b") and is_plugin("plugin:x") and not is_plugin("runs/wm") and not is_plugin(None)
    with pytest.raises(ValueError, match="python:MODULE:FACTORY or plugin:NAME"):
        PluginSpec.parse("python:no_factory")


def test_both_tables_and_both_forms_go_through_one_helper():
    assert import_named("gymnast.world_model.base:load_world_model") is load_world_model
    assert {"tiny-video"} <= set(entry_point_names("gymnast.world_models"))
    assert isinstance(load_world_model("plugin:tiny-video"), TinyVideoWorldModel)
    assert isinstance(load_world_model("python:tiny_video_wm.gymnast_plugin:load_world_model"), TinyVideoWorldModel)
    assert isinstance(load_policy("plugin:tiny-policy"), TinyPolicy)
    assert load_plugin("python:builtins:str@text", "none") == "text"


def test_what_cannot_be_loaded_says_why():
    with pytest.raises(ValueError, match="no installed package registers 'nowhere'.*installed there: .*tiny-video"):
        load_world_model("plugin:nowhere")
    with pytest.raises(ValueError, match="has no attribute 'missing'"):
        load_world_model("python:tiny_video_wm.gymnast_plugin:missing")
    with pytest.raises(ValueError, match="lacks context_frames"):
        load_world_model("python:builtins:dict")
    with pytest.raises(ValueError, match="a policy is a torch.nn.Module"):
        load_policy("python:builtins:dict")
    with pytest.raises(ValueError, match="reanchor_every"):
        load_world_model("plugin:tiny-video", reanchor_every=3)
