"""FMI: the generic block adapter, the model-description fixes and the build of the project's FMUs."""
