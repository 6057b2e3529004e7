"""The house error message, shared by every stage: "<what> must be <expected>. Got <actual>. <hint>"."""


def must_be(what: str, expected: str, got: object, hint: str = "") -> str:
    """Format a user-facing error message naming the argument, the expectation and what came."""
    message = f"{what} must be {expected}. Got {got!r}."
    return f"{message} {hint}" if hint else message


class NotFittedError(ValueError, AttributeError):
    """A model was used before `fit` (as scikit-learn's NotFittedError)."""
