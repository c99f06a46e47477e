"""Figures (matplotlib, optional extra ``plot``; imported lazily with a clear error when missing)."""

from companion.errors import CompanionError


def require_matplotlib():
    """Import matplotlib with the Agg backend, or raise a one-line CompanionError."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise CompanionError("plotting needs matplotlib: pip install 'companion[plot]'") from None
    return plt


def save_figure(fig, path, plt, dpi: int = 110) -> None:
    """Save and close ``fig``; a path that cannot be written is a one-line CompanionError."""
    try:
        fig.savefig(path, dpi=dpi)
    except OSError as exc:
        raise CompanionError(f"{path}: cannot write plot ({exc.strerror or exc})") from None
    finally:
        plt.close(fig)
