"""The scene stage: experiment schema, geometry, the Mitsuba scene, the reference render and
its cache, and the shader inputs rendered from the same scene."""
