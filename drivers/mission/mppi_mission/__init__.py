"""mppid-mission: missions for mppid (plan, reference, runner, links)."""
