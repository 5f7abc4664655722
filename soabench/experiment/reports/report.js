// The report page's script (soabench/experiment/reports/html.py): sortable tables, a figure enlarged on a click,
// image and status checks written on <body> for a headless browser.
"use strict";
(function(){
const body=document.body;
window.addEventListener("error",function(e){body.dataset.status="error: "+e.message;});
function key(td){const t=td.textContent.trim().replace(/\u2212/g,"-");
  const n=parseFloat(t.replace(/[^0-9eE+\-.]/g," ").trim().split(" ")[0]);
  return isNaN(n)||!/^[\-+]?[0-9.]/.test(t)?[1,t.toLowerCase()]:[0,n];}
function sortBy(table,col,th){
  const tb=table.tBodies[0], rows=Array.from(tb.rows), asc=!th.classList.contains("asc");
  table.querySelectorAll("th").forEach(h=>h.classList.remove("asc","desc"));th.classList.add(asc?"asc":"desc");
  rows.sort(function(a,b){const x=key(a.cells[col]),y=key(b.cells[col]);
    const c=x[0]-y[0]||(x[1]<y[1]?-1:x[1]>y[1]?1:0);return asc?c:-c;});
  rows.forEach(r=>tb.appendChild(r));}
document.querySelectorAll("table.sortable").forEach(function(t){
  Array.from(t.tHead.rows[0].cells).forEach(function(th,i){th.addEventListener("click",function(){sortBy(t,i,th);});});});
const m=/sort=(\d+):(\d+)/.exec(location.hash);
if(m){const t=document.querySelectorAll("table.sortable")[+m[1]];if(t)sortBy(t,+m[2],t.tHead.rows[0].cells[+m[2]]);}
const zoom=document.getElementById("zoom");
if(zoom){const big=zoom.querySelector("img");
  document.querySelectorAll("figure img, .md img").forEach(function(img){img.addEventListener("click",function(){
    big.src=img.src;big.alt=img.alt;zoom.hidden=false;});});
  zoom.addEventListener("click",function(){zoom.hidden=true;big.removeAttribute("src");});
  document.addEventListener("keydown",function(e){if(e.key==="Escape")zoom.hidden=true;});}
function images(){const imgs=Array.from(document.querySelectorAll("main img"));
  const ok=imgs.filter(i=>i.complete&&i.naturalWidth>0).length;
  body.dataset.images=ok+"/"+imgs.length;}
window.addEventListener("load",function(){images();if(body.dataset.status=="loading")body.dataset.status="ok";});
body.dataset.tables=String(document.querySelectorAll("table.sortable").length);
})();
