"""The <model-viewer> embed snippet of an orbit (export/orbit.py's embed_snippet)."""

from windowshop.export.orbit import embed_snippet

LIMITED = {"camera-orbit": "90.0deg 75deg auto", "min-camera-orbit": "60.0deg auto auto",
           "max-camera-orbit": "120.0deg auto auto"}


def test_the_snippet_carries_both_models_and_the_orbit():
    got = embed_snippet(LIMITED, "https://shop.example/a.glb", "https://shop.example/a.usdz")
    assert got == ('<model-viewer src="https://shop.example/a.glb" '
                   'ios-src="https://shop.example/a.usdz" camera-controls '
                   'camera-orbit="90.0deg 75deg auto" min-camera-orbit="60.0deg auto auto" '
                   'max-camera-orbit="120.0deg auto auto"></model-viewer>')


def test_without_a_usdz_there_is_no_ios_src_and_a_free_orbit_has_camera_orbit_only():
    got = embed_snippet({"camera-orbit": "10.0deg 75deg auto"}, "model.glb")
    assert got == ('<model-viewer src="model.glb" camera-controls '
                   'camera-orbit="10.0deg 75deg auto"></model-viewer>')


def test_addresses_are_escaped_as_attribute_values():
    got = embed_snippet({}, 'https://x.example/m.glb?a=1&b="2"<', "it's.usdz")
    assert 'src="https://x.example/m.glb?a=1&amp;b=&quot;2&quot;&lt;"' in got
    assert 'ios-src="it&#x27;s.usdz"' in got
