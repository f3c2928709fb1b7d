"""The site's build hook: adds the pages generated from the code (`hoh_cosim.docsite`) to the
files MkDocs builds, so the reference and the results are rebuilt at every `mkdocs build`."""

from __future__ import annotations

from mkdocs.structure.files import File, Files

from hoh_cosim.docsite import reference, results


def on_files(files: Files, config) -> Files:
    for path, text in {**reference.pages(), **results.pages()}.items():
        files.append(File.generated(config, path, content=text))
    return files
