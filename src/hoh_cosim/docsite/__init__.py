"""The documentation site's generated pages: the reference (`reference`) and the results
(`results`), built from the code and from the runs' own summaries. `docs/hooks.py` adds them to
the site at every `mkdocs build`; `python -m hoh_cosim.docsite results` re-measures the results."""
