"""The one error of the study package: what the user must change to create, join or report a study."""


class StudyError(ValueError):
    """A study cannot be created, joined or reported; the message says what to change."""
