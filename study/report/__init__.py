"""The report stage: figures and report writers (``report.md`` and its images) of each study.
Export and its checks are ``study.export``."""
