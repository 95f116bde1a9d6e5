"""The generated model's free-text name is quoted as the standard library quotes an XML attribute
(the oracle: ``xml.sax.saxutils.quoteattr``), and survives MuJoCo's parser."""

from __future__ import annotations

from xml.sax.saxutils import quoteattr

import mujoco
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.model.humanoid import _quoted, build_mjcf, canonical_skeleton


@settings(max_examples=300, deadline=None)
@given(st.text(alphabet=st.sampled_from(list("ab &<>\"'\n\r\t;#é")), max_size=20))
def test_names_are_quoted_as_quoteattr_quotes_them(name):
    assert _quoted(name) == quoteattr(name)


@pytest.mark.parametrize("name", ['a "quoted" name', "it's", "both ' and \"", "<&>"])
def test_a_model_of_any_name_loads_with_that_name(name):
    xml = build_mjcf(canonical_skeleton(), model_name=name)
    assert mujoco.MjModel.from_xml_string(xml).names.split(b"\0")[0].decode() == name
