"""Synthetic quad-camera scenes with exact ground truth: textures, objects (planar and curved), the renderer,
built-in scenes."""

from tpnet_gpu.scenes.curved import Cylinder, Sphere, curved
from tpnet_gpu.scenes.library import demo_scene, random_scene
from tpnet_gpu.scenes.objects import Patch, Scene, Sky, plane
from tpnet_gpu.scenes.render import Optics, Rendered, Sensor, render

__all__ = ["Cylinder", "Optics", "Patch", "Rendered", "Scene", "Sensor", "Sky", "Sphere", "curved", "demo_scene",
           "plane", "random_scene", "render"]
