"""List the built-in scenes, then the gallery scenes (TOML files shipped with flagsim), one per
line with a one-line description. Any of them can be run with `flagsim run NAME --out DIR`."""

from __future__ import annotations


def configure(p):
    del p  # no options


def run(args):
    import flagsim

    scenes = flagsim.Scene.builtins()
    gallery = flagsim.Scene.gallery()
    width = max((len(name) for name in [*scenes, *gallery]), default=0)
    for name, summary in sorted(scenes.items()):
        print(f"{name:<{width}}  {summary}")
    if gallery:
        print("\ngallery (TOML scenes in flagsim/gallery/, also examples/scenes/):")
        for name, summary in sorted(gallery.items()):
            print(f"{name:<{width}}  {summary}")
    return 0
