"""Layer 9: the HTML pages (jinja2 templates) and their figures."""
