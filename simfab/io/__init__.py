"""File formats at simfab's boundary: USD stages, MJCF scenes, meshes, rendering, atomic writes."""
