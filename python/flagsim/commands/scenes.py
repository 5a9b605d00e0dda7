"""List the built-in scenes, one per line with a one-line description. Any of them can be run
with `flagsim run NAME --out DIR`."""

from __future__ import annotations


def configure(p):
    del p  # no options


def run(args):
    import flagsim

    scenes = flagsim.Scene.builtins()
    width = max((len(name) for name in scenes), default=0)
    for name, summary in sorted(scenes.items()):
        print(f"{name:<{width}}  {summary}")
    return 0
