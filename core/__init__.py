"""Pure numerics of Zoopraxis: numpy, scipy and OpenCV only, never bpy or mathutils."""
