"""Reports: self-contained HTML pages with embedded figures, and their browser check.

matplotlib is imported only inside this subpackage's functions, so the core stays light.
"""

from .browser import BrowserCheck, check_in_browser, find_browser
from .html import HtmlReport, fig_to_files

__all__ = ["BrowserCheck", "HtmlReport", "check_in_browser", "fig_to_files", "find_browser"]
