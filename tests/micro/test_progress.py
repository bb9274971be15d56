"""The one progress indicator (issue 36): a tqdm bar on a terminal, plain lines elsewhere."""
import io

from micro.common.progress import Progress, is_terminal, progress_bar


class _Tty(io.StringIO):
    def isatty(self):
        return True


def test_plain_lines_every_tenth_when_not_a_terminal():
    out = io.StringIO()
    bar = progress_bar(total=37, desc="batch x", unit="RVE", file=out)
    assert isinstance(bar, Progress) and not is_terminal(out)
    for _ in range(37):
        bar.update(1)
    bar.close()
    lines = out.getvalue().splitlines()
    assert "\r" not in out.getvalue()
    assert lines[0].startswith("batch x: 0 % (0/37 RVE)")
    assert lines[-1].startswith("batch x: 100 % (37/37 RVE)")
    assert len(lines) == 11                      # 0, 10, ..., 100 %: one line per tenth


def test_lines_without_total_and_with_bar_n_and_postfix():
    out = io.StringIO()
    bar = progress_bar(desc="diagnose", unit="model", file=out, leave=False)
    for _ in range(23):
        bar.update(1)
    bar.close()
    assert [ln.split(" model")[0] for ln in out.getvalue().splitlines()] == [
        "diagnose: 1", "diagnose: 2", "diagnose: 5", "diagnose: 10", "diagnose: 20",
        "diagnose: 23"]
    out = io.StringIO()
    bar = progress_bar(total=3, desc="cell", unit="case", file=out)
    bar.n = 2
    bar.set_postfix_str("CG it 5")
    bar.total = bar.n
    bar.refresh()
    bar.close()
    assert out.getvalue().splitlines()[-1].endswith("CG it 5")
    for x in progress_bar(range(4), file=io.StringIO()):      # an iterable, as tqdm
        pass


def test_a_bar_on_a_terminal_and_nothing_when_disabled():
    tty = _Tty()
    bar = progress_bar(total=10, desc="bar", file=tty, mininterval=0)
    for _ in range(10):
        bar.update(1)
    bar.close()
    assert "\r" in tty.getvalue() and "|" in tty.getvalue()      # tqdm's own bar
    out = io.StringIO()
    with progress_bar(total=5, file=out, disable=True) as bar:
        bar.update(5)
    assert out.getvalue() == ""
