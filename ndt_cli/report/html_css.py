"""The report's style sheet: a surveyor's registration report on screen, on a phone and on A4.

Wide screens and print show real tables (print at 7.5 pt, headers repeated, rows and figures
not split); below 720 px every data table stacks each row into a card whose cells are preceded
by their column's name, and the key-value tables put the value under its label, so that a page
400 px wide never scrolls sideways.
"""

CSS = """
:root { --ok: #1b7a32; --ok-bg: #e3f4e6; --warn: #8a5a00; --warn-bg: #fff1cc;
  --bad: #b3261e; --bad-bg: #fde4e1; --info: #34506f; --info-bg: #e4ebf3;
  --grey: #555; --rule: #c8cdd2; --head: #eef1f4; }
* { box-sizing: border-box; }
html { color: #111; background: #fff; }
body { font: 14px/1.45 "Helvetica Neue", Arial, "Liberation Sans", "DejaVu Sans", sans-serif;
  max-width: 1200px; margin: 0 auto; padding: 24px; }
h1 { font-size: 1.6em; margin: 0 0 0.4em; }
h2 { font-size: 1.2em; margin: 1.6em 0 0.5em; padding-bottom: 0.2em;
  border-bottom: 2px solid #234; }
h3 { font-size: 1em; margin: 1.2em 0 0.4em; }
header { border-bottom: 3px solid #234; padding-bottom: 0.8em; }
code, pre { font-family: "DejaVu Sans Mono", "Liberation Mono", Consolas, monospace;
  font-size: 0.9em; overflow-wrap: anywhere; }
table { border-collapse: collapse; width: 100%; }
th, td { padding: 3px 6px; text-align: left; vertical-align: top;
  overflow-wrap: anywhere; word-break: normal; }
th, td.word { overflow-wrap: normal; }
td.name { overflow-wrap: anywhere; min-width: 7em; }
table.meta th, table.kv th { width: 16em; font-weight: 600; color: var(--grey); }
table.meta td, table.kv td, table.kv th { border-bottom: 1px solid #e3e6ea; }
table.kv { width: auto; min-width: 50%; }
table.data { font-size: 0.88em; }
table.data th { background: var(--head); border: 1px solid var(--rule); font-weight: 600;
  vertical-align: bottom; }
table.data thead tr.group th { text-align: center; }
table.data td { border: 1px solid var(--rule); }
table.data tbody tr:nth-child(even) td { background: #f8f9fa; }
td.num { text-align: right; white-space: nowrap; font-variant-numeric: tabular-nums; }
td.empty { color: #888; text-align: center; }
.st { display: inline-block; padding: 0 5px; border: 1px solid; border-radius: 3px;
  font-weight: 600; white-space: nowrap; }
.st-ok { color: var(--ok); background: var(--ok-bg); }
.st-warn { color: var(--warn); background: var(--warn-bg); }
.st-bad { color: var(--bad); background: var(--bad-bg); }
.st-info { color: var(--info); background: var(--info-bg); border-style: dashed; }
.st-none { color: var(--grey); background: #f1f1f1; }
.verdict { margin: 1em 0; padding: 0.6em 0.9em; border: 2px solid; border-radius: 4px;
  font-size: 1.05em; }
.verdict p { margin: 0; font-size: 1.1em; }
.verdict ul { margin: 0.4em 0 0; padding-left: 1.3em; }
.verdict.ok { color: var(--ok); background: var(--ok-bg); }
.verdict.remarks { color: var(--warn); background: var(--warn-bg); }
.verdict.bad { color: var(--bad); background: var(--bad-bg); }
.verdict li { color: #111; }
p, li, figcaption, summary { overflow-wrap: anywhere; }
.legend, figcaption, footer, .note { color: var(--grey); font-size: 0.88em; }
.table-wrap { overflow-x: auto; }
figure { margin: 1em 0; text-align: center; }
figure img { max-width: 100%; height: auto; border: 1px solid var(--rule); }
.cards { display: grid; grid-template-columns: repeat(auto-fill, minmax(min(100%, 440px), 1fr));
  gap: 12px; }
figure.link { margin: 0; padding: 8px; border: 1px solid var(--rule); border-radius: 4px;
  text-align: left; }
figure.link figcaption { color: #111; font-size: 0.88em; overflow-wrap: anywhere; }
figure.link figcaption b { display: block; margin-bottom: 2px; }
details { margin: 0.3em 0; }
summary { cursor: pointer; color: var(--info); }
.key { display: inline-block; width: 0.9em; height: 0.9em; vertical-align: -0.1em;
  border-radius: 2px; }
pre.config { background: #f6f8fa; border: 1px solid var(--rule); padding: 8px;
  white-space: pre-wrap; overflow-wrap: anywhere; }
footer { margin-top: 2em; border-top: 1px solid var(--rule); padding-top: 0.5em; }
@media screen and (max-width: 720px) {
  body { padding: 10px; font-size: 13px; }
  table.meta, table.meta tbody, table.meta tr, table.meta th, table.meta td,
  table.kv, table.kv tbody, table.kv tr, table.kv th, table.kv td { display: block;
    width: auto; min-width: 0; }
  table.kv th, table.meta th { border-bottom: none; padding-bottom: 0; }
  table.data, table.data tbody, table.data tr { display: block; width: auto; }
  table.data thead { display: none; }
  table.data tr { border: 1px solid var(--rule); border-radius: 4px; margin: 0 0 8px; }
  table.data tbody tr:nth-child(even) td { background: none; }
  table.data td { display: grid; grid-template-columns: minmax(6em, 40%) 1fr; gap: 6px;
    border: none; border-bottom: 1px solid #eceff2; text-align: left; white-space: normal; }
  table.data td::before { content: attr(data-label); font-weight: 600; color: var(--grey);
    overflow-wrap: normal; }
  table.data td.name { display: block; background: var(--head); font-weight: 600; }
  table.data td.name::before { display: block; font-weight: 400; }
  table.data td.empty { text-align: left; }
  table.data td > .st { justify-self: start; }
  .table-wrap { overflow-x: visible; }
}
@page { size: A4; margin: 14mm 12mm; }
@media print {
  * { -webkit-print-color-adjust: exact; print-color-adjust: exact; }
  body { font-size: 9pt; max-width: none; padding: 0; }
  table.data { font-size: 7.5pt; }
  th, td { padding: 2px 3px; }
  td.name { min-width: 5.5em; }
  .table-wrap { overflow: visible; }
  h2 { break-after: avoid; }
  tr, figure, .verdict, table.kv { break-inside: avoid; }
  thead { display: table-header-group; }
  figure img { max-height: 230mm; width: auto; }
  .cards { display: block; }
  figure.link { margin: 0 0 3mm; }
  figure.link img { max-width: 120mm; }
  section.appendix { break-before: page; }
}
"""
