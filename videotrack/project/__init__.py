"""Projects: the configuration schema and its sections, project folders with inheritance
and trials, the never-overwrite-an-input check, and the content identity of inputs."""
