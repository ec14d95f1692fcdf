"""What is drawn: the GPU-ready scene layout, built-in scenes, users' model files (through
trimesh), spatial clusters, camera paths.
"""
