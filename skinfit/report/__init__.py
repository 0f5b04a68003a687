"""The static HTML report (Jinja2) written from saved results."""
