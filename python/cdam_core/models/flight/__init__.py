"""Flight models of [flights]: ``physics.QuadPhysics`` (kind ``quad_physics``)."""
